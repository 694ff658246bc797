"""Evaluator of the completion task: metrics from the test run, results.md and figures
(interface: :mod:`lit3d.cli.registry`)."""
from __future__ import annotations

from pathlib import Path

from lit3d.completion.report import write_figures, write_results  # noqa: F401
from lit3d.utils.evaluation import Evaluation


def protocol(task, datamodule) -> Evaluation:
    """Nothing beyond the module's own test metrics (it logs everything, paired intervals included)."""
    return Evaluation()


def write_artefacts(evaluation: Evaluation, out_dir: Path) -> list[Path]:
    """No files beyond results.md and the figures."""
    return []
