"""Evaluator of the completion task: metrics from the test run, results.md and figures
(interface: :mod:`lit3d.runtime.registry`).

``settings`` (the config's ``evaluation`` node, saved in the checkpoint): ``surface``, the sizes of the
test's surface metrics (``points``, ``fscore_at``, ``seed``; null = off), which the module computes
during the test once :func:`prepare` has set them up.
"""
from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

from lit3d.completion.report import write_figures, write_results  # noqa: F401
from lit3d.utils.evaluation import Evaluation


def prepare(task, settings: Mapping) -> None:
    """The test's surface metrics with ``settings["surface"]`` (None or absent: off)."""
    task.use_surface_metrics(settings.get("surface"))


def protocol(task, datamodule, settings: Mapping) -> Evaluation:
    """Nothing beyond the module's own test metrics (it logs everything, paired intervals included)."""
    return Evaluation()


def write_artefacts(evaluation: Evaluation, out_dir: Path) -> list[Path]:
    """No files beyond results.md and the figures."""
    return []


def validation_protocol(trainer, task, datamodule, settings: Mapping) -> Evaluation:
    """``lit3d-eval split=val``: nothing beyond the module's own ``val/`` metrics."""
    return Evaluation()
