"""Evaluator of the completion task: metrics from the test run, results.md and figures
(interface: :mod:`lit3d.cli.registry`)."""
from __future__ import annotations

from lit3d.completion.report import write_figures, write_results  # noqa: F401


def protocol(task, datamodule) -> dict[str, float]:
    """Metrics beyond the module's own test metrics (none yet: the module logs everything)."""
    return {}
