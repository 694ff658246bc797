"""Building a task's LightningModule and DataModule from their config nodes, with plain arguments
(what a checkpoint stores loads with ``weights_only=True``), and the task metadata a checkpoint keeps."""
from __future__ import annotations

import importlib
from collections.abc import Callable
from typing import Any

from omegaconf import DictConfig, OmegaConf

from lit3d.runtime.config_checks import config_problem
from lit3d.runtime.errors import UserError
from lit3d.utils.checkpoints import first_line
from lit3d.utils.errors import Lit3dError


# checkpoints written before the one-room-per-task layout name their module by its old path
LEGACY_MODULES = {
    "lit3d.tasks.completion": "lit3d.completion.module",
    "lit3d.tasks.quality": "lit3d.quality.module",
    "lit3d.tasks.canonical": "lit3d.canonical.module",
}


def import_object(path: str) -> Any:
    """Import ``pkg.module.Name`` (or ``pkg.module:Name``); old module paths are mapped to the new rooms."""
    module, name = _split_target(path)
    return getattr(importlib.import_module(module), name)


def to_plain(cfg: DictConfig | dict | None) -> dict:
    """Resolved plain-dict copy of a config node (safe to store in checkpoints)."""
    if cfg is None:
        return {}
    if isinstance(cfg, DictConfig):
        return OmegaConf.to_container(cfg, resolve=True)
    return dict(cfg)


def task_kwargs(task_cfg: DictConfig | dict) -> dict:
    """Constructor arguments of a task config (``cfg.task``): everything but ``_target_``."""
    return {k: v for k, v in to_plain(task_cfg).items() if k != "_target_"}


def task_meta(cfg: DictConfig) -> dict:
    """What a checkpoint stores of the task: ``cfg.task`` (``_target_`` + constructor arguments)
    plus ``cfg.task_info`` (``name``, ``monitor``, ``monitor_mode``), as plain values."""
    return {**to_plain(cfg.get("task_info")), **to_plain(cfg.task)}


def _construct(group: str, make: Callable[[], Any]) -> Any:
    """``make()``; a config problem (:func:`config_problem`: a bad option value, an unknown keyword)
    becomes a one-line :class:`UserError` naming the config group; anything else is passed on."""
    try:
        return make()
    except (Lit3dError, ValueError, TypeError) as exc:
        if not config_problem(exc):
            raise
        raise UserError(f"{group} config: {first_line(exc, type(exc).__name__)}") from exc


def _instantiate_plain(node: DictConfig | dict):
    """``hydra.utils.instantiate`` of a config node with plain (dict/list) arguments (not recursive:
    nested ``_target_`` nodes, e.g. the quality task's ``cross_data``, stay configs), so that what
    a LightningModule saves as hyper-parameters loads with ``weights_only=True``; the constructor's
    own ValueError/TypeError is passed on unwrapped."""
    from hydra.errors import InstantiationException
    from hydra.utils import instantiate

    plain = to_plain(node)
    plain["_target_"] = ".".join(filter(None, _split_target(plain["_target_"])))
    try:
        return instantiate(OmegaConf.create(plain), _convert_="all", _recursive_=False)
    except InstantiationException as exc:  # Hydra wraps the constructor's own error
        raise (exc.__cause__ if isinstance(exc.__cause__, (ValueError, TypeError, Lit3dError)) else exc) from exc


def _split_target(path: str) -> tuple[str, str]:
    module, _, name = path.replace(":", ".").rpartition(".")
    return LEGACY_MODULES.get(module, module), name


def build_task(task_cfg: DictConfig | dict):
    """The LightningModule of ``cfg.task``: ``hydra.utils.instantiate`` with plain arguments."""
    return _construct("task", lambda: _instantiate_plain(task_cfg))


def build_datamodule(data_cfg: DictConfig | dict):
    """Instantiate a DataModule from its config (plain values only)."""
    return _construct("data", lambda: _instantiate_plain(data_cfg))
