"""Pieces shared by the Hydra entry points: config dir, task building, loggers, metadata."""
from __future__ import annotations

import importlib
import logging
import sys
from pathlib import Path
from typing import Any

import lightning.pytorch as pl
import torch
from hydra.utils import instantiate
from omegaconf import DictConfig, OmegaConf

log = logging.getLogger("lit3d")

CONF_DIR = str(Path(__file__).resolve().parents[2] / "conf")
# keys of a task config read by the CLI and not passed to the LightningModule
CLI_TASK_KEYS = ("_target_", "name", "monitor", "monitor_mode")
META_KEY = "lit3d"


class UserError(Exception):
    """A problem the user can fix (bad path, missing option): printed as one line."""


def import_object(path: str) -> Any:
    """Import ``pkg.module.Name`` (or ``pkg.module:Name``)."""
    module, _, name = path.replace(":", ".").rpartition(".")
    return getattr(importlib.import_module(module), name)


def to_plain(cfg: DictConfig | dict | None) -> dict:
    """Resolved plain-dict copy of a config node (safe to store in checkpoints)."""
    if cfg is None:
        return {}
    if isinstance(cfg, DictConfig):
        return OmegaConf.to_container(cfg, resolve=True)
    return dict(cfg)


def task_kwargs(task_cfg: DictConfig | dict) -> dict:
    """Constructor arguments of a task config: everything but the CLI keys."""
    return {k: v for k, v in to_plain(task_cfg).items() if k not in CLI_TASK_KEYS}


def build_task(task_cfg: DictConfig | dict) -> pl.LightningModule:
    """Instantiate the LightningModule named by ``task_cfg._target_`` with plain kwargs."""
    cls = import_object(task_cfg["_target_"])
    return cls(**task_kwargs(task_cfg))


def build_datamodule(data_cfg: DictConfig | dict) -> pl.LightningDataModule:
    """Instantiate a DataModule from its config (plain values only)."""
    return instantiate(OmegaConf.create(to_plain(data_cfg)), _convert_="all")


def read_checkpoint_meta(ckpt_path: str | Path) -> dict:
    """The lit3d metadata stored in a checkpoint (task, data config, W&B id).

    Loads with ``weights_only=True`` (memory-mapped so large checkpoints are cheap).
    """
    path = Path(ckpt_path)
    if not path.is_file():
        raise UserError(f"{path}: checkpoint not found")
    try:
        ckpt = torch.load(path, map_location="cpu", weights_only=True, mmap=True)
    except Exception as exc:  # corrupt or not a torch file
        raise UserError(f"{path}: not a readable checkpoint ({type(exc).__name__}: {exc})") from exc
    meta = ckpt.get(META_KEY)
    if not isinstance(meta, dict):
        raise UserError(f"{path}: not a lit3d checkpoint (no '{META_KEY}' metadata)")
    return meta


class MetadataCallback(pl.Callback):
    """Stores what evaluation needs in every checkpoint: task, data config, W&B run id."""

    def __init__(self, task_cfg: dict, data_cfg: dict, wandb_id: str | None):
        self.meta = {"task": task_cfg, "data": data_cfg, "wandb_id": wandb_id}

    def on_save_checkpoint(self, trainer, pl_module, checkpoint: dict) -> None:
        checkpoint[META_KEY] = self.meta


def run_cli(fn, cfg: DictConfig) -> Any:
    """Run ``fn(cfg)``; a :class:`UserError` becomes one line on stderr and exit 2.

    ``HYDRA_FULL_ERROR=1`` or ``debug=true`` shows the traceback instead.
    """
    import os

    from omegaconf.errors import MissingMandatoryValue

    from datamodules.cache import DataError

    try:
        missing = sorted(OmegaConf.missing_keys(cfg))
        if missing:  # before any work or logging: the one line is all the user sees
            raise UserError(f"missing value for {missing[0]}: set {missing[0]}=... on the command line")
        return fn(cfg)
    except (UserError, DataError, MissingMandatoryValue) as exc:
        if os.environ.get("HYDRA_FULL_ERROR") == "1" or cfg.get("debug", False):
            raise
        if isinstance(exc, MissingMandatoryValue):
            key = getattr(exc, "full_key", "") or "a required option"
            exc = UserError(f"missing value for {key}: set {key}=... on the command line")
        print(f"error: {exc}", file=sys.stderr)
        sys.exit(2)
