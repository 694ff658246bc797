"""Composing the Hydra config outside a Hydra run, and checking a command line's overrides before it
starts (a config group option that does not exist, a key that is not in the config)."""
from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from omegaconf import DictConfig

from lit3d.runtime.errors import UserError
from lit3d.runtime.eval_settings import override_problem, stale_task_keys
from lit3d.runtime.key_hints import misspelt_key
from lit3d.utils.config_dir import config_dir

CONF_DIR = str(config_dir())


def config_groups(conf_dir: str = CONF_DIR) -> dict[str, list[str]]:
    """Config groups of ``conf/`` (Hydra's own ``hydra/`` excluded) -> their option names."""
    groups = {}
    for d in sorted(Path(conf_dir).iterdir()):
        if d.is_dir() and d.name != "hydra":
            groups[d.name] = sorted(p.stem for p in d.glob("*.yaml"))
    return groups


def check_group_overrides(args: Sequence[str], conf_dir: str = CONF_DIR) -> None:
    """Raise :class:`UserError` when an override picks an option a config group does not have.

    ``experiment=nope`` -> ``experiment=nope: no such experiment config; known: ...``. Sweep
    lists (``task=a,b``) are checked item by item; sweep functions (``choice(...)``,
    ``glob(...)``), interpolations and ``null`` are left to Hydra.
    """
    groups = config_groups(conf_dir)
    for arg in args:
        if arg.startswith("-") or "=" not in arg:
            continue
        key, value = arg.split("=", 1)
        key = key.lstrip("+~").split("@", 1)[0]
        if key not in groups or value in ("", "null") or any(c in value for c in "()*[]{}$"):
            continue
        for option in value.split(","):
            if option not in groups[key]:
                known = ", ".join(groups[key]) or "(none)"
                raise UserError(f"{key}={option}: no such {key} config (conf/{key}/{option}.yaml); known: {known}")


def compose_config(config_name: str, overrides=(), return_hydra_config: bool = False, conf_dir=None):
    """``conf/<config_name>.yaml`` composed with Hydra ``overrides`` outside a Hydra run (a fresh
    global Hydra, cleared again after), from :data:`CONF_DIR` unless ``conf_dir`` is given.
    Hydra's errors (a key not in the config ...) propagate."""
    from hydra import compose, initialize_config_dir
    from hydra.core.global_hydra import GlobalHydra

    GlobalHydra.instance().clear()
    try:
        with initialize_config_dir(config_dir=str(conf_dir or CONF_DIR), version_base="1.3"):
            return compose(config_name, overrides=list(overrides), return_hydra_config=return_hydra_config)
    finally:
        GlobalHydra.instance().clear()


def check_composes(args: Sequence[str], config_name: str, conf_dir: str = CONF_DIR) -> DictConfig | None:
    """Raise :class:`UserError` when the overrides do not compose (e.g. a key that is not in the
    config: ``trainer.max_epoch=3``), with Hydra's first two lines as the message (a moved evaluation
    setting, ``task.mesh_baselines=[]``: one line naming ``evaluation.mesh_baselines``,
    :mod:`lit3d.runtime.eval_settings`); else return the composed config (with its ``hydra`` node).

    Skipped for multiruns and Hydra's own flags (``-m``, ``--cfg`` ...): Hydra reports those.
    """
    if any(a.startswith("-") for a in args):
        return None
    from hydra.errors import HydraException

    try:
        composed = compose_config(config_name, args, return_hydra_config=True, conf_dir=conf_dir)
    except HydraException as exc:
        moved = override_problem(args, lambda rest: compose_config(config_name, rest, conf_dir=conf_dir))
        if moved:  # a task.KEY that is an evaluation setting now, or evaluation.* without a task
            raise UserError(moved) from exc
        misspelt = misspelt_key(str(exc), args, lambda rest: compose_config(config_name, rest, conf_dir=conf_dir))
        if misspelt:  # trainer.max_epoch=3: trainer.max_epochs named, not Hydra's "+trainer.max_epoch"
            raise UserError(misspelt) from exc
        lines = [ln.strip() for ln in str(exc).strip().splitlines() if ln.strip()]
        raise UserError("; ".join(ln.rstrip(".") for ln in lines[:2]) or type(exc).__name__) from exc
    stale = stale_task_keys(composed)  # an experiment that still sets an evaluation setting under task:
    if stale:
        raise UserError(stale)
    return composed
