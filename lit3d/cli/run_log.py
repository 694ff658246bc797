"""The CSV log every ``lit3d-train`` run keeps, and the ``curves.png`` drawn from it.

Whatever ``logger=`` says (``wandb``, ``tensorboard``, ``csv``, ``none``), a run logs its metrics to
``<run dir>/csv/version_N/metrics.csv`` too (a resumed run adds a version), and ends by drawing
``<run dir>/curves.png`` beside ``metrics.json``: one panel per ``train/`` and ``val/`` metric
against step (:mod:`lit3d.utils.curves`). So curves can be seen without an account or a viewer.
``logger=none`` means no logger besides this CSV log.
"""
from __future__ import annotations

import logging
from pathlib import Path

from lit3d.utils.curves import write_curves

log = logging.getLogger("lit3d")

CSV_NAME = "csv"          # <run dir>/csv/version_N/metrics.csv (also conf/logger/csv.yaml's name)
CURVES_FILE = "curves.png"


def is_csv_logger(logger) -> bool:
    return any(cls.__name__ == "CSVLogger" for cls in type(logger).__mro__)


def with_csv_logger(loggers: list, output_dir: Path) -> list:
    """``loggers`` plus a CSVLogger writing under ``output_dir`` (none added when one is configured)."""
    if any(is_csv_logger(lg) for lg in loggers):
        return loggers
    from lightning.pytorch.loggers import CSVLogger

    return [*loggers, CSVLogger(save_dir=str(output_dir), name=CSV_NAME)]


def csv_files(loggers: list) -> list[Path]:
    """The ``metrics.csv`` of every version of the run's CSV loggers, oldest version first."""
    files: list[Path] = []
    for lg in loggers:
        if is_csv_logger(lg):
            lg.save()  # flush what is buffered
            files += sorted(Path(lg.log_dir).parent.glob("version_*/metrics.csv"), key=_version)
    return files


def _version(path: Path) -> int:
    """``.../version_3/metrics.csv`` -> 3 (-1 for a version that is not a number)."""
    number = path.parent.name.removeprefix("version_")
    return int(number) if number.isdigit() else -1


def write_run_curves(loggers: list, output_dir: Path, title: str) -> Path | None:
    """Draw ``<output_dir>/curves.png`` from the CSV logs; a failure is logged, never raised (the
    run's results are already written)."""
    try:
        path = write_curves(csv_files(loggers), output_dir / CURVES_FILE, title)
    except Exception as exc:  # a picture must not fail a finished run
        log.warning("no %s: %s: %s", CURVES_FILE, type(exc).__name__, exc)
        return None
    if path is None:
        log.info("no %s: the CSV log holds no train/ or val/ value (e.g. debug=fdr)", CURVES_FILE)
    else:
        log.info("wrote %s", path)
    return path
