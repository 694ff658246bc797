"""Collect the metrics.json of a multirun's jobs into one markdown table.

Used as a Hydra callback by every multirun (``hydra.callbacks.collect`` in ``conf/hydra/``;
the configs in ``sweeps/`` set its metrics and title; written when the multirun ends) and by
hand: :func:`collect` (from the checkout: ``python -m studies.sweeps.collect SWEEP_DIR [METRIC ...]``).
:class:`StudyStorage` makes a kept Optuna study (``hydra.sweeper.storage=sqlite:///optuna.db``) work and
resume without replacing earlier trial dirs; :class:`KeepEarlierJobs` refuses any multirun into a sweep dir
that holds an earlier multirun's job dirs.
"""
from __future__ import annotations

import json
import logging
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import yaml
from hydra.experimental.callback import Callback

from lit3d.utils.tables import fmt, markdown_table
from lit3d.utils.io import atomic_write_text

log = logging.getLogger("lit3d.sweeps")


def _override_key(override: str) -> str:
    return override.split("=", 1)[0].lstrip("+~")


def _normalise_override(override: str) -> str:
    """``key=True`` -> ``key=true``: Hydra writes YAML booleans of a sweep as Python's."""
    key, sep, value = override.partition("=")
    return f"{key}{sep}{value.lower()}" if value in ("True", "False") else override


def _swept_on_command_line(multirun_yaml: Path) -> set[str]:
    """Keys given several values on the multirun's command line (e.g. ``seed=42,0,1``)."""
    if not multirun_yaml.is_file():
        return set()
    cfg = (yaml.safe_load(multirun_yaml.read_text()) or {}).get("hydra", {})
    task = ((cfg.get("overrides") or {}).get("task")) or []
    return {_override_key(str(o)) for o in task if "," in str(o).partition("=")[2] and "{" not in str(o)}


def job_label(job_dir: Path, ignore: Sequence[str] = ("hydra.", "+sweep", "experiment")) -> str:
    """The job's swept settings, e.g. ``task.nets.k=50, task.nets.attention=none``.

    Read from ``.hydra/overrides.yaml``; only the keys of the sweep's
    ``hydra.sweeper.params`` (from ``.hydra/hydra.yaml``) and of the command line's swept keys
    (several values, from the sweep dir's ``multirun.yaml``) are kept, so the fixed
    command-line overrides shared by every job do not clutter the row. Without a
    sweeper record, every override but ``ignore`` is kept.
    """
    path = job_dir / ".hydra" / "overrides.yaml"
    if not path.is_file():
        return job_dir.name
    overrides = [str(o) for o in (yaml.safe_load(path.read_text()) or [])]
    hydra_path = job_dir / ".hydra" / "hydra.yaml"
    swept: set[str] = set()
    if hydra_path.is_file():
        hydra_cfg = (yaml.safe_load(hydra_path.read_text()) or {}).get("hydra", {})
        swept = {k.lstrip("+~") for k in ((hydra_cfg.get("sweeper") or {}).get("params") or {})}
        swept |= _swept_on_command_line(job_dir.parent / "multirun.yaml")
    if swept:
        kept = [o for o in overrides if _override_key(o) in swept]
    else:
        kept = [o for o in overrides if not any(o.lstrip("+~").startswith(p.lstrip("+")) for p in ignore)]
    return ", ".join(_normalise_override(o) for o in kept) or "(defaults)"


WIDE = 12  # more metrics than this: the per-metric table is laid out one row per metric


def collect(sweep_dir: str | Path, metrics: Sequence[str] | None = None,
            thesis: dict[str, Any] | None = None, title: str = "Sweep results") -> str:
    """Markdown tables of a multirun's jobs, written to ``sweep_results.md`` and returned.

    ``metrics`` given (the ``sweeps/`` configs): one row per job (its overrides), one column per metric.
    ``metrics`` None: every ``test/...`` key found in any job; the jobs table then holds each job's
    monitored value (``monitor`` of its metrics.json), and the metrics follow in a second table with one
    row per metric and one column per job whenever there are more than ``WIDE`` (a completion job has
    hundreds: a row of them per job is unreadable). ``thesis`` maps a row label (the override string) to
    the thesis's figure for that setting. Jobs without metrics.json (failed or running) are listed as such.
    """
    sweep_dir = Path(sweep_dir)
    jobs = sorted((p for p in sweep_dir.iterdir() if p.is_dir() and (p / ".hydra").is_dir()),
                  key=lambda p: (len(p.name), p.name))
    results = {}
    for job in jobs:
        mpath = job / "metrics.json"
        results[job] = json.loads(mpath.read_text()) if mpath.is_file() else None
    named = metrics is not None
    if metrics is None:
        metrics = sorted({k for r in results.values() if r for k in r if k.startswith("test/")})
    tall = not named and len(metrics) > WIDE
    monitors = sorted({str(r["monitor"]) for r in results.values() if r and r.get("monitor")})
    if tall:  # one column: the monitored value (or whether the job finished)
        header = ["job", "setting", f"{' / '.join(monitors)} (monitored)" if monitors else "status"]
    else:
        header = ["job", "setting", *metrics]
    header += ["thesis"] if thesis else []
    rows = []
    for job, res in results.items():
        label = job_label(job)
        if not res:
            cells = ["no metrics.json"] * (1 if tall else len(metrics))
        elif tall:
            cells = [fmt(res.get("monitored_value")) if monitors else "done"]
        else:
            cells = [fmt(res.get(m)) for m in metrics]
        rows.append([job.name, label, *cells, *([_thesis_cell(thesis, label)] if thesis else [])])
    text = f"# {title}\n\nSweep dir: `{sweep_dir}`\n\n" + markdown_table(header, rows) + "\n"
    if tall:
        done = [(job, res) for job, res in results.items() if res]
        text += (f"\n## Test metrics: one row per metric ({len(metrics)}), one column per job\n\n"
                 + markdown_table(["metric", *[job.name for job, _ in done]],
                                  [[m, *[fmt(res.get(m)) for _, res in done]] for m in metrics]) + "\n")
    by_setting = over_seeds({job_label(j): r for j, r in results.items()}, metrics)
    if by_setting:
        text += "\n## Mean ± sd over seeds (sd of the jobs' values, ddof 1)\n\n"
        if tall:
            labels = list(by_setting)
            text += ("Seeds per setting: " + "; ".join(f"{lb}: {by_setting[lb][0]}" for lb in labels) + "\n\n"
                     + markdown_table(["metric", *labels],
                                      [[m, *[by_setting[lb][1][i] for lb in labels]] for i, m in enumerate(metrics)])
                     + "\n")
        else:
            head = ["setting", "seeds", *metrics] + (["thesis"] if thesis else [])
            srows = [[label, str(n), *cells] + ([_thesis_cell(thesis, label)] if thesis else [])
                     for label, (n, cells) in by_setting.items()]
            text += markdown_table(head, srows) + "\n"
    atomic_write_text(sweep_dir / "sweep_results.md", text)
    return text


def _thesis_cell(thesis: dict[str, Any], label: str) -> str:
    value = thesis.get(label)
    return fmt(value) if isinstance(value, (int, float)) else str(thesis.get(label, "–"))


def over_seeds(results: dict[str, dict | None], metrics: Sequence[str]) -> dict[str, tuple[int, list[str]]]:
    """Jobs whose labels differ only in ``seed=...`` -> ``{setting: (seeds, ["mean ± sd", ...])}``.

    Empty unless some setting ran with more than one seed; jobs without metrics are left out.
    """
    import numpy as np

    groups: dict[str, list[dict]] = {}
    for label, res in results.items():
        parts = [p for p in label.split(", ") if not p.startswith("seed=")]
        if res is not None:
            groups.setdefault(", ".join(parts) or "(defaults)", []).append(res)
    if not any(len(v) > 1 for v in groups.values()):
        return {}
    out = {}
    for setting, rows in groups.items():
        cells = []
        for m in metrics:
            v = np.array([r[m] for r in rows if isinstance(r.get(m), (int, float))], dtype=np.float64)
            cells.append("–" if not len(v) else f"{v.mean():.3f} ± {v.std(ddof=1):.3f}" if len(v) > 1 else f"{v[0]:.3f}")
        out[setting] = (len(rows), cells)
    return out


class CollectResults(Callback):
    """Hydra callback: write ``sweep_results.md`` into the sweep dir when the multirun ends.

    On by default for every multirun (``conf/hydra/default.yaml`` and ``eval.yaml``:
    ``hydra.callbacks.collect``); a table that cannot be made is a warning, not a failed multirun.
    """

    def __init__(self, metrics: Sequence[str] | None = None, thesis: dict | None = None, title: str = "Sweep results"):
        self.metrics = list(metrics) if metrics else None
        self.thesis = dict(thesis) if thesis else None
        self.title = title

    def on_multirun_end(self, config, **kwargs) -> None:
        sweep_dir = Path(config.hydra.sweep.dir)
        if not sweep_dir.is_dir():
            return
        try:
            print(collect(sweep_dir, self.metrics, self.thesis, self.title))
        except Exception as exc:  # the jobs ran: a summary problem must not fail the multirun
            log.warning("%s: no sweep_results.md (%s: %s); re-collect with lit3d.sweeps.collect('%s')",
                        sweep_dir, type(exc).__name__, exc, sweep_dir)


def prepare_study_storage(url: str) -> None:
    """Make the Optuna RDB storage at ``url`` (``sqlite:///optuna.db``) one that optuna 2.10 opens.

    optuna 2.10 (the last version ``hydra-optuna-sweeper`` 1.x takes) stamps a new database's schema
    version (alembic's ``alembic_version`` table) on a connection it never commits. SQLAlchemy 1.x
    committed it by itself; SQLAlchemy 2 (which alembic >= 1.16 needs) rolls it back, and optuna's next
    check found no version: an ``AssertionError`` in ``get_current_version`` before the first trial.
    Here the tables are made and the version stamped in a committed transaction, once, before the
    sweeper opens the storage; a storage that has its version already is left as it is."""
    import os

    import alembic.config
    import alembic.migration
    import alembic.script
    import optuna
    import sqlalchemy
    from optuna.storages._rdb import models

    engine = sqlalchemy.create_engine(url)
    try:
        with engine.connect() as conn:
            if alembic.migration.MigrationContext.configure(conn).get_current_revision() is not None:
                return
        models.BaseModel.metadata.create_all(engine)
        rdb = os.path.dirname(optuna.storages._rdb.storage.__file__)  # optuna's own migrations
        config = alembic.config.Config(os.path.join(rdb, "alembic.ini"))
        config.set_main_option("script_location", os.path.join(rdb, "alembic").replace("%", "%%"))
        script = alembic.script.ScriptDirectory.from_config(config)
        with engine.begin() as conn:  # committed when the block ends
            alembic.migration.MigrationContext.configure(conn).stamp(script, script.get_current_head())
    finally:
        engine.dispose()


def earlier_job_dirs(sweep_dir: Path) -> list[str]:
    """The job (trial) dirs an earlier multirun left in ``sweep_dir`` (``0/``, ``1/`` ... with a ``.hydra/``), in order."""
    if not sweep_dir.is_dir():
        return []
    return sorted((p.name for p in sweep_dir.iterdir() if p.is_dir() and (p / ".hydra").is_dir()),
                  key=lambda n: (len(n), n))


def refuse_earlier_jobs(config) -> None:
    """Stop the multirun (one line, exit 2) when its sweep dir holds the job dirs of an earlier one:
    Hydra numbers a multirun's job dirs from 0, so the new jobs would train or evaluate afresh in
    the earlier jobs' dirs and replace their results (a resumed Optuna study too)."""
    from omegaconf import OmegaConf

    sweep_dir = Path(str(config.hydra.sweep.dir))
    earlier = earlier_job_dirs(sweep_dir)
    if not earlier:
        return
    shown = ", ".join(earlier[:5]) + (", ..." if len(earlier) > 5 else "")
    storage = OmegaConf.select(config, "hydra.sweeper.storage", default=None)
    what = (f"holds the trial dirs of an earlier sweep ({shown}); a resumed study ({storage}) numbers its trial dirs"
            if storage else f"holds the job dirs of an earlier multirun ({shown}); a new multirun numbers its job dirs")
    print(f"error: {sweep_dir}: {what} from 0 again and would replace them: leave hydra.sweep.dir to its default "
          "(a new timestamped folder) or choose another one", file=sys.stderr, flush=True)
    sys.exit(2)


class KeepEarlierJobs(Callback):
    """Hydra callback, on for every multirun (``conf/hydra/default.yaml``, ``conf/hydra/eval.yaml``:
    ``hydra.callbacks.earlier_jobs``): a sweep dir that holds the job dirs of an earlier multirun
    (``hydra.sweep.dir=X`` given again) is refused with one line and exit 2 before any job runs
    (:func:`refuse_earlier_jobs`); before, the second multirun's jobs replaced the first's results."""

    def on_multirun_start(self, config, **kwargs) -> None:
        refuse_earlier_jobs(config)


class StudyStorage(Callback):
    """Hydra callback, on for every multirun (``conf/hydra/default.yaml``: ``hydra.callbacks.study_storage``);
    does nothing unless the Optuna sweeper keeps its study (``hydra.sweeper.storage=sqlite:///...``). Then,
    before the sweeper opens the storage: :func:`prepare_study_storage`; and a sweep dir that holds the
    trial dirs of an earlier run (``0/``, ``1/`` ...) is refused with one line and exit 2: a resumed study
    numbers its trial dirs from 0 again and would replace them (the default sweep dir is a new
    timestamped folder per run)."""

    def on_multirun_start(self, config, **kwargs) -> None:
        from omegaconf import OmegaConf

        storage = OmegaConf.select(config, "hydra.sweeper.storage", default=None)
        if not storage:
            return
        refuse_earlier_jobs(config)  # before the database is touched (also where earlier_jobs is turned off)
        prepare_study_storage(str(storage))
