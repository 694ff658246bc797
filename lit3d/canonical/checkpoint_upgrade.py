"""Canonical checkpoints written before the task's and the data's settings became config nodes, read as
today's: the one place that knows the old layouts.

:func:`upgrade_checkpoint` rewrites a loaded checkpoint dict in place and returns it: its
``hyper_parameters`` (:func:`upgrade_hparams`) and, in its lit3d metadata, the task config and the data
config (:func:`datamodules.canonical.flat_config.upgrade_data_config`). A checkpoint of today's layout, or
of another task, comes back unchanged. Every loader of a canonical checkpoint calls it: ``lit3d-eval``
(:func:`lit3d.cli.common.read_checkpoint`), the API and ``lit3d-reconstruct --canonical``
(:func:`lit3d.reconstruct.pipeline.load_task`) and ``task.init_weights``
(:meth:`lit3d.canonical.module.CanonicalTask.load_initial_weights`).
"""
from __future__ import annotations

from collections.abc import Mapping

from datamodules.canonical.flat_config import upgrade_data_config
from lit3d.utils.checkpoints import META_KEY

TASK_TARGET = "lit3d.canonical.module.CanonicalTask"


def is_canonical(ckpt: Mapping) -> bool:
    """Whether a checkpoint dict holds the canonical task (by its lit3d metadata)."""
    task = (ckpt.get(META_KEY) or {}).get("task") or {}
    return task.get("name") == "canonical" or task.get("_target_") == TASK_TARGET


def upgrade_hparams(hparams: Mapping) -> dict:
    """The task's hyper-parameters of a checkpoint in today's layout (unchanged when already so)."""
    return dict(hparams)


def upgrade_checkpoint(ckpt: dict) -> dict:
    """``ckpt`` (a loaded checkpoint dict) with its hyper-parameters, task config and data config in
    today's layout, when it is a canonical checkpoint; in place, returned."""
    if not isinstance(ckpt, dict) or not is_canonical(ckpt):
        return ckpt
    if "hyper_parameters" in ckpt:
        ckpt["hyper_parameters"] = upgrade_hparams(ckpt["hyper_parameters"])
    meta = ckpt[META_KEY]
    if isinstance(meta.get("task"), Mapping):
        keep = {k: v for k, v in meta["task"].items() if k in ("_target_", "name", "monitor", "monitor_mode")}
        meta["task"] = {**upgrade_hparams({k: v for k, v in meta["task"].items() if k not in keep}), **keep}
    if isinstance(meta.get("data"), Mapping):
        meta["data"] = upgrade_data_config(meta["data"])
    return ckpt
