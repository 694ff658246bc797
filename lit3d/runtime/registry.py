"""Task name -> the task room's evaluator module. The LightningModule class comes from the task
config's ``_target_``.

An evaluator module (``lit3d/<task>/evaluator.py``) provides (``settings``: the run's evaluation
settings, the config's ``evaluation`` node as a plain dict, :mod:`lit3d.runtime.eval_settings`; the
LightningModule does not hold them):

- ``prepare(task, settings) -> None``: before ``trainer.test`` (the completion task's surface metrics
  are set up here; a no-op for the others);
- ``protocol(task, datamodule, settings) -> Evaluation`` (:class:`lit3d.utils.evaluation.Evaluation`):
  metrics computed after ``trainer.test`` from what the module's test metrics gathered (retrieval,
  baselines, cross-validation), on every rank, plus in-memory artefacts for the writers below;
- ``validation_protocol(trainer, task, datamodule, settings) -> Evaluation``: ``lit3d-eval split=val``'s
  artefacts after the validation (the canonical task's validation predictions; empty for the others);
- ``write_artefacts(evaluation, out_dir) -> list[Path]``: files beyond the tables (rank 0);
- ``write_results(metrics, out_dir) -> Path``: results.md in the thesis's table layout;
- ``write_figures(task, datamodule, out_dir, n, evaluation) -> list[Path]``: labelled PNGs.

``lit3d-eval`` and ``lit3d-train`` (after testing) both run it through
:func:`lit3d.cli.evaluation.run_evaluation`.
"""
from __future__ import annotations

import importlib
from types import ModuleType

EVALUATORS = {
    "completion": "lit3d.completion.evaluator",
    "quality": "lit3d.quality.evaluator",
    "canonical": "lit3d.canonical.evaluator",
    "body": "lit3d.body.evaluator",
}


def evaluator_module(task_name: str) -> ModuleType:
    """The task room's evaluator module (see the module docstring)."""
    if task_name not in EVALUATORS:
        raise KeyError(f"unknown task '{task_name}' (known: {', '.join(sorted(EVALUATORS))})")
    return importlib.import_module(EVALUATORS[task_name])
