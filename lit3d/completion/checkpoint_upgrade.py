"""Completion checkpoints written before the task's and the data's settings became config nodes, read as
today's: the one place that knows the old layouts.

    upgrade_hparams({"nets": {...}, "lr_g": 1e-3, "adversarial": False, "adversarial_start_epoch": 6, ...})
    -> {"nets": {...}, "optimizer": {"lr_g": 1e-3}, "adversarial": {"use": False, "start_epoch": 6}, ...}

:func:`upgrade_checkpoint` rewrites a loaded checkpoint dict in place and returns it: its
``hyper_parameters`` (:func:`upgrade_hparams`) and, in its lit3d metadata, the task config and the data
config (:func:`datamodules.completion.flat_config.upgrade_data_config`). A checkpoint of today's layout, or of
another task, comes back unchanged. Every loader of a completion checkpoint calls it: ``lit3d-eval`` and a
resume (:func:`lit3d.runtime.checkpoints.read_checkpoint`), ``lit3d-reconstruct``, ``lit3d.load`` and the zoo
(:func:`lit3d.reconstruct.pipeline.load_task`).
"""
from __future__ import annotations

from collections.abc import Mapping

from datamodules.completion.flat_config import upgrade_data_config
from lit3d.utils.checkpoints import META_KEY
from lit3d.utils.settings_nodes import nest_flat_keys

TASK_TARGET = "lit3d.completion.module.CompletionTask"

# the evaluation settings that checkpoints written before the ``evaluation`` node hold among the task's
# hyper-parameters, with the constructor's defaults then (lit3d-eval reads them from the task config)
EVALUATION_LEGACY = {"surface": None}

# a flat task key of the old layout -> (its node, its key there) (lit3d.completion.settings)
FLAT_TASK_KEYS = {
    **{k: ("optimizer", k) for k in ("lr_g", "lr_d", "betas", "eps", "loss_scale")},
    **{k: ("loss", k) for k in ("alpha", "gamma", "zeta", "stage_weight")},
    **{k: ("adversarial", k) for k in ("critic_steps", "gp_lambda", "gp_every", "critic_concat", "gp_precision")},
    "adversarial": ("adversarial", "use"), "adversarial_start_epoch": ("adversarial", "start_epoch"),
    **{k: ("panels", k) for k in ("image_every_n_epochs", "mesh_every_n_epochs")},
}


def is_completion(ckpt: Mapping) -> bool:
    """Whether a checkpoint dict holds the completion task (by its lit3d metadata)."""
    task = (ckpt.get(META_KEY) or {}).get("task") or {}
    return task.get("name") == "completion" or task.get("_target_") == TASK_TARGET


def upgrade_hparams(hparams: Mapping, keep_evaluation: bool = False) -> dict:
    """The task's hyper-parameters (or task config) of a checkpoint in today's layout: the flat keys of
    :data:`FLAT_TASK_KEYS` moved into their nodes; the evaluation settings of :data:`EVALUATION_LEGACY`
    dropped (``keep_evaluation``: kept, for the task config). Today's layout comes back unchanged."""
    kept = {k: v for k, v in hparams.items() if keep_evaluation or k not in EVALUATION_LEGACY}
    return nest_flat_keys(kept, FLAT_TASK_KEYS, lambda k, v: k in FLAT_TASK_KEYS and not isinstance(v, Mapping))


def upgrade_checkpoint(ckpt: dict) -> dict:
    """``ckpt`` (a loaded checkpoint dict) with its hyper-parameters, task config and data config in today's
    layout, when it is a completion checkpoint; in place, returned."""
    if not isinstance(ckpt, dict) or not is_completion(ckpt):
        return ckpt
    if isinstance(ckpt.get("hyper_parameters"), Mapping):
        ckpt["hyper_parameters"] = upgrade_hparams(ckpt["hyper_parameters"])
    meta = ckpt[META_KEY]
    if isinstance(meta.get("task"), Mapping):
        meta["task"] = upgrade_hparams(meta["task"], keep_evaluation=True)
    if isinstance(meta.get("data"), Mapping):
        meta["data"] = upgrade_data_config(meta["data"])
    return ckpt
