"""Task name -> report module. The LightningModule class comes from the task config's _target_."""
from __future__ import annotations

import importlib
from types import ModuleType

REPORTS = {
    "completion": "lit3d.reports.completion",
    "quality": "lit3d.reports.quality",
    "canonical": "lit3d.reports.canonical",
}


def report_module(task_name: str) -> ModuleType:
    """The module with ``write_results(metrics, out_dir)`` and ``write_figures(task, dm, out_dir)``."""
    if task_name not in REPORTS:
        raise KeyError(f"unknown task '{task_name}' (known: {', '.join(sorted(REPORTS))})")
    return importlib.import_module(REPORTS[task_name])
