"""Evaluator of the canonical task (interface: :mod:`lit3d.runtime.registry`): retrieval scores and the
non-learned mesh baselines after the test run, results.md and figures.

:func:`protocol` reads what :class:`~lit3d.canonical.module.CanonicalTask` gathered during the
test (``task.test_outputs``, DDP-correct) and returns ``test/retrieval/<source>/<nn|ft|st|e|dcg>``
(and ``.../seconds`` for the mesh baselines) for the sources

- ``model`` (or ``unet`` when the task is the plain U-Net, ``arch=unet``): the predicted canonical
  depth, back-projected to a surface, then the CM-BOF-style descriptor;
- ``input``: the posed input depth (and ``input_outline``, with ``prediction_smooth_px`` > 0: the posed
  input smoothed the same way as the prediction); ``target``: the true canonical depth (1.00 by construction: one
  image per subject); ``target_jitter``: the true canonical rendered with the camera turned by up to
  ``ceiling_jitter_deg`` degrees per item (the ceiling that is not trivial);
- ``chance``: random distances;
- each of ``mesh_baselines`` (cmds, smacof, nmds, gps, posed): the non-learned canonical forms of
  the full test meshes, one per unique (subject, pose), from ``datamodule.normalized_mesh``.

:func:`write_artefacts` saves the fold's held-out items (the ``heldout`` artefact of
:func:`protocol`) to ``<run dir>/heldout.npz`` (:mod:`lit3d.canonical.heldout`) for the pooled
cross-validated protocol (:mod:`lit3d.canonical.pooled`); with ``lit3d-eval split=val``,
:func:`validation_protocol` gives the validation items' in the same layout.

``settings`` are the run's evaluation settings (the config's ``evaluation`` node, saved in the checkpoint:
``retrieval``: descriptor config or null = off, ``retrieval_min_subjects``, ``chance_trials``,
``ceiling_jitter_deg``, ``mesh_baselines``, ``baseline_landmarks``, ``baseline_max_vertices``,
``baseline_smacof_eps``, ``prediction_smooth_px``: the prediction's depth smoothed inside its silhouette
before it is scored and saved, :mod:`lit3d.canonical.smoothing`); the task itself gives only its ``arch``
(the prediction row's name) and ``mask_threshold`` (where its predicted mask is).
"""
from __future__ import annotations

import logging
import time
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import torch

from lit3d.canonical.baselines import baseline_retrieval
from lit3d.canonical.heldout import HELDOUT_FILE, heldout_arrays, item_ids, save_heldout, settings_of
from lit3d.canonical.report import write_figures, write_results  # noqa: F401
from lit3d.canonical.smoothing import smooth_prediction, smoothing_of
from lit3d.metrics.depth import composite_depth
from lit3d.metrics.retrieval import chance_scores, retrieval_scores
from lit3d.retrieval.descriptor import DescriptorConfig, distance_matrix_from_depths
from lit3d.utils.data_hooks import GivesMeshes, ListsHeldOut, RendersTurnedCanonical
from lit3d.utils.evaluation import Evaluation

log = logging.getLogger("lit3d")

LOGGED_SCORES = ("nn", "ft", "st", "e", "dcg", "seconds")
# the retrieval source name of a task's own predictions, by task.arch
PREDICTION_SOURCE = {"canonical": "model", "unet": "unet"}


def prepare(task, settings: Mapping) -> None:
    """Nothing to set up before the test: the module gathers every test item (``task.test_outputs``)."""


def protocol(task, datamodule, settings: Mapping) -> Evaluation:
    """Metrics ``{"test/retrieval/<source>/<score>": value}`` from the task's gathered test outputs
    (none when retrieval is off (``evaluation.retrieval=null``), nothing was tested, or fewer than
    ``retrieval_min_subjects`` test subjects have 2+ items) and, on rank 0, the ``heldout``
    artefact (:func:`heldout_items`). ``settings``: the evaluation settings (module doc). Call on
    every process (the gathered outputs are synchronised across DDP ranks)."""
    if settings.get("retrieval") is None:
        return Evaluation()
    outputs = scored_outputs(task, settings)
    if not outputs:
        return Evaluation()
    held = heldout_items(task, outputs, datamodule, settings)
    results = retrieval_results(settings, outputs, datamodule, source=prediction_source(task),
                                mask_threshold=float(task.hparams.mask_threshold))
    metrics = {f"test/retrieval/{source}/{k}": float(scores[k])
               for source, scores in results.items() for k in LOGGED_SCORES if k in scores}
    return Evaluation(metrics, {"heldout": held} if held else {})


def scored_outputs(task, settings: Mapping) -> dict[str, torch.Tensor]:
    """The task's gathered test outputs (:data:`lit3d.canonical.module.TEST_OUTPUTS`) on the CPU in dataset
    order (DDP ranks hand in interleaved shares), the prediction's depth smoothed as the settings'
    ``prediction_smooth_px`` says: what retrieval scores and ``heldout.npz`` saves. ``{}`` when nothing
    was tested. Call on every process (the outputs are synchronised across ranks)."""
    outputs = task.test_outputs.compute()
    if not outputs:
        return {}
    order = torch.argsort(outputs["index"].cpu())
    outputs = {k: v.cpu()[order] for k, v in outputs.items()}
    outputs["pred_depth"] = smooth_prediction(outputs["pred_depth"], outputs["pred_mask"], smoothing_of(settings),
                                              float(task.hparams.mask_threshold))
    return outputs


def prediction_source(task) -> str:
    """The retrieval row of the task's own predictions: ``model``, or ``unet`` for the plain U-Net."""
    return PREDICTION_SOURCE.get(task.hparams.arch, "model")


def heldout_items(task, outputs: dict[str, torch.Tensor], datamodule, settings: Mapping) -> dict | None:
    """This fold's held-out items (:func:`lit3d.canonical.heldout.heldout_arrays`) for the pooled
    protocol (:mod:`lit3d.canonical.pooled`), with the settings it scores them with (``settings`` and
    the task's ``mask_threshold``); None off rank 0 or for a datamodule that does not list its
    held-out items."""
    trainer = getattr(task, "_trainer", None)
    if (trainer is not None and not trainer.is_global_zero) or not isinstance(datamodule, ListsHeldOut):
        return None
    return _heldout(task, outputs, datamodule, settings, datamodule.held_out_ids(), datamodule.split.fold,
                    datamodule.split.n_folds)


def _heldout(task, outputs: dict[str, torch.Tensor], datamodule, settings: Mapping, expected, fold: int,
             n_folds: int) -> dict:
    """:func:`lit3d.canonical.heldout.heldout_arrays` of ``outputs`` with ``expected`` item ids as fold ``fold``
    of ``n_folds``: the subjects named by the datamodule, its data config, the task's prediction source, and
    ``settings`` with the task's ``mask_threshold``."""
    return heldout_arrays(outputs, {i: s for s, i in datamodule.subject_index.items()}, expected,
                          prediction_source(task), dict(datamodule.hparams), fold, n_folds,
                          settings_of({"mask_threshold": task.hparams.mask_threshold, **settings}))


def validation_protocol(trainer, task, datamodule, settings: Mapping) -> Evaluation:
    """``lit3d-eval split=val``: the validation items' predictions as the ``heldout`` artefact (saved as
    ``heldout.npz`` by :func:`write_artefacts`), so that ``lit3d-summary --pooled`` scores settings on
    validation people with the thesis descriptor instead of on the test set. The validation loader goes
    through the task's test step (the gathered outputs, ``settings``' smoothing applied); every
    validation item is its own expected set (fold 0 of 1). None for a datamodule that does not list
    its held-out items. Call on every process."""
    if not isinstance(datamodule, ListsHeldOut):
        return Evaluation()
    trainer.test(task, dataloaders=datamodule.val_dataloader(), weights_only=True, verbose=False)
    outputs = scored_outputs(task, settings)
    if not outputs or not trainer.is_global_zero:
        return Evaluation()
    names = {i: s for s, i in datamodule.subject_index.items()}
    expected = item_ids([names[int(i)] for i in outputs["subject_idx"]], outputs["pose"], outputs["view"])
    return Evaluation({}, {"heldout": _heldout(task, outputs, datamodule, settings, expected.tolist(), 0, 1)})


def write_artefacts(evaluation: Evaluation, out_dir: Path) -> list[Path]:
    """``<out_dir>/heldout.npz`` from the ``heldout`` artefact, when :func:`protocol` made one."""
    held = evaluation.artefacts.get("heldout")
    if not held:
        return []
    path = save_heldout(Path(out_dir) / HELDOUT_FILE, dict(held))
    log.info("held-out items: %s", path)
    return [path]


def retrieval_results(settings: Mapping, outputs: dict[str, torch.Tensor], datamodule=None, source: str = "model",
                      mask_threshold: float = 0.5) -> dict[str, dict]:
    """``{source: retrieval scores}`` (see :func:`lit3d.metrics.retrieval.retrieval_scores`) of the
    depth sources and the mesh baselines; ``{}`` when too few subjects. ``settings``: the evaluation
    settings (module doc); ``outputs``: ``task.test_outputs.compute()`` on the CPU; ``source``: the
    prediction row's name (:func:`prediction_source`); ``mask_threshold``: the task's."""
    labels = outputs["subject_idx"].numpy()
    if (np.bincount(labels) >= 2).sum() < settings["retrieval_min_subjects"]:
        log.info("retrieval skipped: fewer than %d test subjects with 2+ items", settings["retrieval_min_subjects"])
        return {}
    results = depth_retrieval(settings, outputs, labels, source, mask_threshold)
    results.update(jittered_target(settings, outputs, labels, datamodule))
    results.update(mesh_baseline_retrieval(settings, outputs, datamodule))
    return results


def depth_retrieval(settings: Mapping, outputs: dict[str, torch.Tensor], labels: np.ndarray, source: str = "model",
                    mask_threshold: float = 0.5) -> dict[str, dict]:
    """Retrieval scores of the predicted canonical forms (row ``source``, mask at ``mask_threshold``), the
    posed inputs (also smoothed like the prediction when the settings smooth it: ``input_outline``) and
    the true canonical forms (each depth image back-projected to a surface, then the CM-BOF-style
    descriptor), and chance."""
    cfg = DescriptorConfig(**(settings.get("retrieval") or {}))
    sources = {
        source: (outputs["pred_depth"], (outputs["pred_mask"] >= mask_threshold).float()),
        "input": (outputs["depth"], outputs["mask"]),
        "target": (outputs["canon_depth"], outputs["canon_mask"]),
    }
    sigma = smoothing_of(settings)
    if sigma > 0:  # the posed input scored on its outline too: what the smoothing gives without canonicalisation
        sources["input_outline"] = (smooth_prediction(outputs["depth"], outputs["mask"], sigma), outputs["mask"])
    out = {}
    for name, (d, m) in sources.items():
        dist = distance_matrix_from_depths(composite_depth(d, m)[:, 0].numpy(), m[:, 0].numpy(), cfg)
        out[name] = retrieval_scores(dist, labels)
    out["chance"] = chance_scores(labels, settings["chance_trials"], seed=0)
    return out


def jittered_target(settings: Mapping, outputs: dict[str, torch.Tensor], labels: np.ndarray,
                    datamodule) -> dict[str, dict]:
    """``{"target_jitter": scores}``: the true canonical form of every test item rendered again with the
    camera turned by U(-j, j) degrees (``ceiling_jitter_deg`` = j, seeded per item), through the same
    descriptor. Every pose of a subject has one identical true canonical image, so the plain ``target``
    row is 1.00 by construction; this row is the ceiling a perfect canonical form reaches when its
    image is not pixel-identical. Empty when ``ceiling_jitter_deg`` is 0/absent or the datamodule cannot
    render (``canonical_turned``)."""
    jitter = float(settings.get("ceiling_jitter_deg") or 0.0)
    if not jitter or not isinstance(datamodule, RendersTurnedCanonical):
        return {}
    names = {i: s for s, i in datamodule.subject_index.items()}
    turns = np.random.default_rng(0).uniform(-jitter, jitter, len(labels))
    views = [datamodule.canonical_turned(names[int(s)], int(v), t)
             for s, v, t in zip(outputs["subject_idx"], outputs["view"], turns)]
    depth = np.stack([d for d, _ in views]).astype(np.float32)
    mask = np.stack([m for _, m in views]).astype(np.float32)
    dist = distance_matrix_from_depths(depth, mask, DescriptorConfig(**(settings.get("retrieval") or {})))
    return {"target_jitter": retrieval_scores(dist, labels)}


def mesh_baseline_retrieval(settings: Mapping, outputs: dict[str, torch.Tensor], datamodule) -> dict[str, dict]:
    """Non-learned canonical forms (``mesh_baselines``) of the full test meshes, one per unique
    (subject, pose) of the test items, through the same descriptor (empty when off, or when the
    datamodule cannot give meshes)."""
    methods = list(settings.get("mesh_baselines") or [])
    if not methods:
        return {}
    if not isinstance(datamodule, GivesMeshes):
        log.info("mesh baselines skipped: the datamodule has no normalized_mesh()")
        return {}
    names = {i: s for s, i in datamodule.subject_index.items()}
    keys = sorted({(int(s), int(p)) for s, p in zip(outputs["subject_idx"], outputs["pose"])})
    t0 = time.perf_counter()
    meshes = [datamodule.normalized_mesh(names[s], p) for s, p in keys]
    cfg = DescriptorConfig(**(settings.get("retrieval") or {}))
    out = baseline_retrieval(meshes, [s for s, _ in keys], methods, cfg, settings.get("baseline_max_vertices"),
                             eps=settings.get("baseline_smacof_eps", 1e-4), landmarks=settings.get("baseline_landmarks", 300))
    log.info("mesh baselines %s on %d test shapes: %.0fs", methods, len(keys), time.perf_counter() - t0)
    return out
