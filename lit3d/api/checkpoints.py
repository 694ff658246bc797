"""Load a lit3d checkpoint of any task; write the checkpoint of an untrained model.

    model = load("best.ckpt")        # Completer | CanonicalMapper | QualityPredictor, by the checkpoint's task
    untrained_checkpoint("completion_demo", "tiny.ckpt", ["task.nets.k=10"])   # no training, random weights

Every failure is one :class:`lit3d.reconstruct.depth_io.InputError` (a ``ValueError``) naming the
file: missing, not a checkpoint, not a lit3d checkpoint, a task lit3d does not know. A quality
checkpoint that cannot be used raises :class:`lit3d.quality.predict.QualityCheckpointError` (also a
``ValueError``), as ``lit3d-score --ckpt`` does.
"""
from __future__ import annotations

import io
from collections.abc import Sequence
from pathlib import Path

import lightning.pytorch as pl
import torch
from omegaconf import DictConfig, open_dict

from lit3d.body_fit.regressor import load_regressor
from lit3d.callbacks.metadata import MetadataCallback
from lit3d.runtime.build import build_task, task_meta, to_plain
from lit3d.runtime.compose import check_composes, check_group_overrides
from lit3d.runtime.errors import UserError
from lit3d.runtime.config_checks import ConfigValueError, check_config_values
from lit3d.quality.predict import QualityPredictor, load_predictor
from lit3d.quality.shipped import load_model_file
from lit3d.reconstruct.canonical import CanonicalMapper, load_canonical
from lit3d.reconstruct.depth_io import InputError
from lit3d.reconstruct.pipeline import Completer, load_completer, task_name
from lit3d.utils.checkpoints import META_KEY, load_checkpoint
from lit3d.utils.io import atomic_write_bytes, output_error
from lit3d.zoo import is_zoo_name, zoo_model
from lit3d.zoo import models as zoo_models

TASKS = ("completion", "canonical", "quality")
Model = Completer | CanonicalMapper | QualityPredictor


def checkpoint_task(path: str | Path) -> str:
    """Which task (one of :data:`TASKS`) the lit3d checkpoint at ``path`` holds."""
    ckpt = load_checkpoint(path, InputError)
    meta = ckpt.get(META_KEY) if isinstance(ckpt, dict) else None
    if not isinstance(meta, dict):
        raise InputError(f"{path}: not a lit3d checkpoint (no '{META_KEY}' metadata)")
    name = task_name(meta)
    for task in TASKS:
        if task in name.lower():
            return task
    raise InputError(f"{path}: checkpoint of task '{name}', which lit3d.load does not know (expected one of {TASKS})")


def load(path: str | Path, device: str = "cpu") -> Model:
    """A lit3d checkpoint, in eval mode, as the object its task runs with (``weights_only=True``):

    - completion: :class:`lit3d.reconstruct.pipeline.Completer` (generator, validation-chosen
      threshold, training grid geometry), for :func:`lit3d.complete` / :func:`lit3d.complete_grid`;
    - canonical: :class:`lit3d.reconstruct.canonical.CanonicalMapper`, for
      :func:`lit3d.canonical_form` / :func:`lit3d.canonical_points`;
    - quality: :class:`lit3d.quality.predict.QualityPredictor` (CPU; ``device`` is not used), for
      :func:`lit3d.score`.

    ``path`` may also name a model of the zoo (:func:`lit3d.models`, :mod:`lit3d.zoo`) where no such file
    exists: ``completion-furniture`` loads as a :class:`Completer`, ``body-regressor`` as
    :class:`lit3d.body_fit.regressor.Regressor`, ``cpcd2-phil-fusion`` as
    :class:`lit3d.quality.shipped.ShippedQualityModel`.

    The completion and canonical nets go to :func:`lit3d.export`.
    """
    if is_zoo_name(path):
        return load_zoo(path, device)
    task = checkpoint_task(path)
    if task == "completion":
        return load_completer(path, device)
    if task == "canonical":
        return load_canonical(str(path), device)
    return load_predictor(path)


def load_zoo(name: str, device: str = "cpu"):
    """The zoo model ``name`` loaded as its task uses it (see :func:`load`); a :class:`lit3d.zoo.ZooError` line
    for a name that is not there."""
    model = zoo_model(name)
    if model.task == "body":
        return load_regressor(model.path)
    if model.task == "quality":
        return load_model_file(model.path)
    return load(model.path, device)  # a completion or canonical checkpoint file, read as any other


def models() -> list[dict]:
    """The trained models that ship in the package (:func:`lit3d.zoo.models`): name, task, path, bytes,
    trained_on, command, card. Each name is accepted by :func:`load`."""
    return zoo_models()


def _check_overrides(overrides) -> None:
    if isinstance(overrides, str) or not all(isinstance(o, str) for o in overrides):
        raise InputError(f"overrides: expected a list of 'key=value' strings, got {overrides!r}")


def train_config(overrides: Sequence[str]) -> DictConfig:
    """``conf/train.yaml`` composed with Hydra ``overrides`` (as ``lit3d-train`` would, without running),
    through ``lit3d-train``'s checks: an unknown config option, a key not in the config and a value of the
    wrong type or out of range (:mod:`lit3d.runtime.config_checks`) are one :class:`InputError` line, the
    CLI's, before any net is built."""
    _check_overrides(overrides)
    try:
        check_group_overrides(overrides)
        cfg = check_composes(overrides, "train")
        check_config_values(cfg)
    except (UserError, ConfigValueError) as exc:
        raise InputError(str(exc)) from None
    if cfg is None:  # Hydra's own flags (-m, --cfg): no single config
        raise InputError(f"overrides: Hydra flags are not overrides: {[o for o in overrides if o.startswith('-')]}")
    with open_dict(cfg):
        cfg.pop("hydra", None)  # composed with it for the checks; no Hydra run here
        cfg.paths.output_dir = "."  # Hydra's run dir: no run here
    return cfg


def untrained_checkpoint(experiment: str, path: str | Path, overrides: Sequence[str] = ()) -> Path:
    """Write the checkpoint of an untrained model of ``experiment=NAME`` (``conf/experiment/NAME.yaml``
    plus Hydra ``overrides``, e.g. ``["task.nets.k=10"]``) to ``path``, with the metadata that
    ``lit3d-train`` stores (task and data config, evaluation settings, provenance): for trying the API and
    :func:`lit3d.export` without training. Its predictions are those of random weights.

    A quality model needs its features named (``task.features=[...]``): training selects them.
    The overrides go through ``lit3d-train``'s checks (:func:`train_config`); the checkpoint is written
    through a temp file and a rename. Returns ``path``.
    """
    if not isinstance(experiment, str):
        raise InputError(f"experiment: expected a name of conf/experiment/ (a string), got {type(experiment).__name__}")
    _check_overrides(overrides)
    cfg = train_config([f"experiment={experiment}", *overrides])
    try:
        module = build_task(cfg.task)
    except UserError as exc:  # a net size the constructors refuse: the CLI's task config line
        raise InputError(str(exc)) from None
    ckpt = {"pytorch-lightning_version": pl.__version__, "epoch": 0, "global_step": 0,
            "state_dict": module.state_dict(), "hyper_parameters": dict(module.hparams)}
    module.on_save_checkpoint(ckpt)
    MetadataCallback(task_meta(cfg), to_plain(cfg.data), None,
                     to_plain(cfg.get("evaluation"))).on_save_checkpoint(None, module, ckpt)
    buf = io.BytesIO()
    torch.save(ckpt, buf)
    try:
        return atomic_write_bytes(path, buf.getvalue())
    except OSError as exc:
        raise output_error(path, exc) from None
