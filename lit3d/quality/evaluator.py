"""Evaluator of the quality task (interface: :mod:`lit3d.runtime.registry`): the thesis's protocol
after ``trainer.test``, results.md and scatter plots.

:func:`protocol` adds to the module's ``test/ours/...`` metrics

- ``test/<baseline>/<kind>[/<shape>]``: each baseline (Chamfer, Hausdorff, MSE, PSNR, MS-SSIM,
  single best feature) fitted / chosen on the datamodule's training split, scored on its test split;
- with ``cv``: ``test/cv/<method>/<kind>[/<shape>]``, leave-one-shape-out over the datamodule's
  whole matrix (tables 4.2-4.4), the learned methods ``cv_methods`` (``cv_epochs`` epochs) + the baselines;
- with ``cross_data`` (data configs): ``test/cross/<dataset>/<method>/...``, select + train on this
  datamodule's matrix, test on each other dataset (table 4.8).

``settings`` are the run's evaluation settings (the config's ``evaluation`` node, saved in the checkpoint:
``baselines``, ``cv``, ``cv_epochs``, ``cv_methods``, ``cross_data``), not the module's.
Learned methods are the task's own settings through :mod:`lit3d.quality.task_methods` and are
trained by the one trainer (:mod:`lit3d.quality.trainer`). What the figures need beyond the
metrics (the leave-one-shape-out predictions) travels in the returned
:class:`~lit3d.utils.evaluation.Evaluation`'s artefacts; the module carries no results.
"""
from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np
import torch

from lit3d.features.matrix import FeatureMatrix
from lit3d.quality.correlation import shape_corr_metrics
from lit3d.quality.protocol import EvalResult, baseline_methods, cross_dataset, leave_one_shape_out, results_to_metrics
from lit3d.quality.report import write_results, write_scatter_figures
from lit3d.quality.task_methods import cv_methods, task_baselines
from lit3d.utils.evaluation import Evaluation

__all__ = ["protocol", "write_artefacts", "write_figures", "write_results"]


def prepare(task, settings: Mapping) -> None:
    """Nothing to set up before the test: the protocol runs after it."""


def protocol(task, datamodule, settings: Mapping) -> Evaluation:
    """Baselines on the held-out split, and (per the evaluation ``settings``) leave-one-shape-out and
    cross-dataset metrics; see the module docstring for the keys."""
    baselines = task_baselines(settings.get("baselines"))
    train, test = datamodule.split("train"), datamodule.split("test")
    out: dict[str, float] = {}
    artefacts = {}
    for name, method in baseline_methods(test.names, baselines).items():
        pred = method.fit(train).predict(test)
        out.update(shape_corr_metrics(f"test/{name}", pred, test.target, test.shapes))
    if settings.get("cv"):
        results = run_cv(task, datamodule.matrix, settings)
        artefacts["cv"] = results
        out.update(results_to_metrics(results, "test/cv"))
    if settings.get("cross_data"):
        out.update(run_cross(task, datamodule.matrix, settings["cross_data"], settings))
    return Evaluation(out, artefacts)


def write_artefacts(evaluation: Evaluation, out_dir: Path) -> list[Path]:
    """No files beyond results.md and the figures."""
    return []


def validation_protocol(trainer, task, datamodule, settings: Mapping) -> Evaluation:
    """``lit3d-eval split=val``: nothing beyond the module's own ``val/`` metrics."""
    return Evaluation()


def learned_methods(task, fm: FeatureMatrix, settings: Mapping) -> dict:
    """The learned methods of ``settings["cv_methods"]`` (the task's net, optimiser and selection),
    trained for ``settings["cv_epochs"]`` epochs (None: the trainer's)."""
    cfg = task.train_config(settings.get("cv_epochs"))
    return cv_methods(task.hparams, cfg, fm.names, settings.get("cv_methods") or ())


def run_cv(task, fm: FeatureMatrix, settings: Mapping) -> dict[str, EvalResult]:
    """Leave-one-shape-out (tables 4.2-4.4) on ``fm``: the learned methods + the baselines of ``settings``."""
    baselines = task_baselines(settings.get("baselines"))
    methods = dict(learned_methods(task, fm, settings))
    for name in baseline_methods(fm.names, baselines):
        methods[name] = lambda name=name: baseline_methods(fm.names, baselines)[name]
    return leave_one_shape_out(fm, methods)


def load_matrices(data_cfgs) -> dict[str, FeatureMatrix]:
    """Dataset name -> feature matrix of each data config (prepared if needed)."""
    from hydra.utils import instantiate
    from omegaconf import OmegaConf

    out = {}
    for cfg in data_cfgs:
        other = instantiate(OmegaConf.create(dict(cfg)), _convert_="all")
        other.prepare_data()
        other.setup("test")
        out[other.name] = other.matrix
    return out


def run_cross(task, fm: FeatureMatrix, data_cfgs, settings: Mapping) -> dict[str, float]:
    """Select + train on ``fm``; test on each ``data_cfgs`` dataset (table 4.8); "ours_sfs" when
    ``settings["cv_methods"]`` has it, else every learned method."""
    tests = load_matrices(data_cfgs)
    all_methods = learned_methods(task, fm, settings)
    methods = {k: v for k, v in all_methods.items() if k == "ours_sfs"} or all_methods
    out: dict[str, float] = {}
    for dname, per_method in cross_dataset(fm, tests, methods).items():
        out.update(results_to_metrics(per_method, f"test/cross/{dname}"))
    return out


def checkpoint_predictions(task, test: FeatureMatrix) -> Mapping[str, np.ndarray]:
    """The task's predictions on ``test``: ``{"pred": (N,) float64, "target": (N,), "shapes": (N,) str}``."""
    x = torch.as_tensor(test.columns(task.features), dtype=torch.float32, device=task.device)
    task.eval()
    with torch.no_grad():
        pred = task(x).double().cpu().numpy()
    return {"pred": pred, "target": test.target, "shapes": test.shapes}


def write_figures(task, datamodule, out_dir: Path, n: int = 4, evaluation: Evaluation | None = None) -> list[Path]:
    """Scatter plots of predicted vs target per test shape: the checkpoint, and each learned
    leave-one-shape-out method of ``evaluation`` (:func:`protocol`'s result) when it ran one."""
    ours = checkpoint_predictions(task, datamodule.split("test")) if task.net is not None else None
    cv = evaluation.artefacts.get("cv") if evaluation is not None else None
    return write_scatter_figures(ours, cv, out_dir)
