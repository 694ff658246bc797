"""Quality checkpoints written before the DataModule's settings became config nodes, read as today's: the one
place that knows the old layout of their data.

:func:`upgrade_checkpoint` rewrites a loaded checkpoint dict in place and returns it: the data config in its
lit3d metadata and the DataModule's hyper-parameters that Lightning saved beside the task's
(``datamodule_hyper_parameters``), both by :func:`datamodules.quality.flat_config.upgrade_data_config`. The
task's own hyper-parameters kept their layout. A checkpoint of today's layout, or of another task, comes back
unchanged. Its loaders: ``lit3d-eval`` and a resume (:func:`lit3d.runtime.checkpoints.read_checkpoint`),
``lit3d-score --ckpt`` and ``lit3d.load`` (:func:`lit3d.quality.predict.load_predictor`).
"""
from __future__ import annotations

from collections.abc import Mapping

from datamodules.quality.flat_config import upgrade_data_config
from lit3d.utils.checkpoints import META_KEY

DATAMODULE_HPARAMS = "datamodule_hyper_parameters"  # Lightning's key for a DataModule's save_hyperparameters


def is_quality(ckpt: Mapping) -> bool:
    """Whether a checkpoint dict holds a quality task (by its lit3d metadata)."""
    task = (ckpt.get(META_KEY) or {}).get("task") or {}
    return task.get("name") == "quality" or str(task.get("_target_", "")).startswith("lit3d.quality.")


def upgrade_checkpoint(ckpt: dict) -> dict:
    """``ckpt`` (a loaded checkpoint dict) with its data config and DataModule hyper-parameters in today's
    layout, when it is a quality checkpoint; in place, returned."""
    if not isinstance(ckpt, dict) or not is_quality(ckpt):
        return ckpt
    meta = ckpt[META_KEY]
    if isinstance(meta.get("data"), Mapping):
        meta["data"] = upgrade_data_config(meta["data"])
    if isinstance(ckpt.get(DATAMODULE_HPARAMS), Mapping):
        ckpt[DATAMODULE_HPARAMS] = upgrade_data_config(ckpt[DATAMODULE_HPARAMS])
    return ckpt
