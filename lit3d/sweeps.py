"""Collect the metrics.json of a multirun's jobs into one markdown table.

Used as a Hydra callback by the configs in ``sweeps/`` (written when the
multirun ends) and by hand:  ``python -m lit3d.sweeps SWEEP_DIR [METRIC ...]``.
"""
from __future__ import annotations

import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import yaml
from hydra.experimental.callback import Callback

from lit3d.reports.tables import fmt, markdown_table
from lit3d.utils.io import atomic_write_text


def job_label(job_dir: Path, ignore: Sequence[str] = ("hydra.", "+sweep", "experiment")) -> str:
    """The job's sweep overrides, e.g. ``task.nets.top_k=50`` (from .hydra/overrides.yaml)."""
    path = job_dir / ".hydra" / "overrides.yaml"
    if not path.is_file():
        return job_dir.name
    overrides = yaml.safe_load(path.read_text()) or []
    kept = [o for o in overrides if not any(o.lstrip("+~").startswith(p.lstrip("+")) for p in ignore)]
    return ", ".join(kept) or "(defaults)"


def collect(sweep_dir: str | Path, metrics: Sequence[str] | None = None,
            thesis: dict[str, Any] | None = None, title: str = "Sweep results") -> str:
    """Markdown table: one row per job (its overrides), one column per metric.

    ``metrics`` None -> every ``test/...`` key found in any job. ``thesis`` maps a
    row label (the override string) to the thesis's figure for that setting.
    Jobs without metrics.json (failed or running) are listed as such.
    """
    sweep_dir = Path(sweep_dir)
    jobs = sorted((p for p in sweep_dir.iterdir() if p.is_dir() and (p / ".hydra").is_dir()),
                  key=lambda p: (len(p.name), p.name))
    results = {}
    for job in jobs:
        mpath = job / "metrics.json"
        results[job] = json.loads(mpath.read_text()) if mpath.is_file() else None
    if metrics is None:
        metrics = sorted({k for r in results.values() if r for k in r if k.startswith("test/")})
    header = ["job", "setting", *metrics] + (["thesis"] if thesis else [])
    rows = []
    for job, res in results.items():
        label = job_label(job)
        cells = [fmt(res.get(m)) if res else "no metrics.json" for m in metrics]
        extra = [fmt(thesis.get(label)) if isinstance(thesis.get(label), (int, float)) else str(thesis.get(label, "–"))] if thesis else []
        rows.append([job.name, label, *cells, *extra])
    text = f"# {title}\n\nSweep dir: `{sweep_dir}`\n\n" + markdown_table(header, rows) + "\n"
    atomic_write_text(sweep_dir / "sweep_results.md", text)
    return text


class CollectResults(Callback):
    """Hydra callback: write ``sweep_results.md`` into the sweep dir when the multirun ends."""

    def __init__(self, metrics: Sequence[str] | None = None, thesis: dict | None = None, title: str = "Sweep results"):
        self.metrics = list(metrics) if metrics else None
        self.thesis = dict(thesis) if thesis else None
        self.title = title

    def on_multirun_end(self, config, **kwargs) -> None:
        sweep_dir = Path(config.hydra.sweep.dir)
        if sweep_dir.is_dir():
            print(collect(sweep_dir, self.metrics, self.thesis, self.title))


if __name__ == "__main__":
    print(collect(sys.argv[1], sys.argv[2:] or None))
