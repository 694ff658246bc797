"""The evaluation settings of a run: the config's top-level ``evaluation`` node.

Each task's ``conf/task/<task>.yaml`` fills it (canonical: the retrieval descriptor, the chance trials,
the mesh baselines; completion: the surface metrics; quality: the baselines, leave-one-shape-out and
cross-dataset protocols); experiments and the command line override it (``evaluation.retrieval.vocab=300``).
The task room's evaluator gets it as an argument (:mod:`lit3d.runtime.registry`); the LightningModule does
not hold it.

- ``lit3d-train`` evaluates with ``cfg.evaluation`` and saves it, resolved, in every checkpoint
  (``checkpoint["lit3d"]["evaluation"]``, :class:`lit3d.callbacks.metadata.MetadataCallback`).
- ``lit3d-eval`` evaluates a checkpoint with the settings it was trained with (:func:`checkpoint_settings`;
  a checkpoint saved before the node existed: the settings among its task's hyper-parameters, over the
  defaults the module's constructor had for them, ``<Module>.evaluation_legacy``), except where the
  command line sets ``evaluation.*``: the command line wins (:func:`with_command_line`). The run log
  says which, once.
- A command line that still sets a moved key under ``task.`` is refused with one line naming the new
  key (:func:`override_problem`, :func:`stale_task_keys`).
"""
from __future__ import annotations

import logging
import re
from collections.abc import Callable, Mapping, Sequence

from omegaconf import DictConfig, OmegaConf

from lit3d.utils.evaluation import legacy_settings
from lit3d.utils.task_hooks import evaluation_legacy

log = logging.getLogger("lit3d")

NODE = "evaluation"
# an override of the evaluation node: evaluation.a.b=v, +evaluation.a=v, ~evaluation.a, evaluation={...}
_OVERRIDE = re.compile(r"^[+~]{0,2}evaluation(?:\.(?P<key>[^=@]+))?(?:=|$)")
_TASK_KEY = re.compile(r"^[+~]{0,2}task\.(?P<key>[A-Za-z_][\w-]*)")
_ABSENT = object()


def command_line_overrides(cfg: DictConfig | None = None) -> list[str]:
    """This command's Hydra overrides: ``cfg.hydra.overrides.task`` of a config composed with its ``hydra``
    node, else Hydra's runtime record, else none."""
    from hydra.core.hydra_config import HydraConfig

    found = OmegaConf.select(cfg, "hydra.overrides.task", default=None) if cfg is not None else None
    if found is not None:  # the config's own record wins over a Hydra state left by another run in this process
        return list(found)
    return list(HydraConfig.get().overrides.task) if HydraConfig.initialized() else []


def command_line_keys(overrides: Sequence[str]) -> list[str]:
    """The ``evaluation`` keys the overrides set, in their order (``"retrieval.vocab"``; ``""``: the whole node)."""
    keys = []
    for arg in overrides:
        m = _OVERRIDE.match(arg)
        if m and (m.group("key") or "") not in keys:
            keys.append(m.group("key") or "")
    return keys


def with_command_line(base: Mapping, evaluation: DictConfig | Mapping | None, keys: Sequence[str]) -> dict:
    """``base`` with the value of each of ``keys`` taken from ``evaluation`` (the composed node, where
    Hydra parsed the command line); a key the node no longer has (``~evaluation.key``) is removed."""
    node = OmegaConf.create(dict(base))
    given = evaluation if isinstance(evaluation, DictConfig) else OmegaConf.create(dict(evaluation or {}))
    for key in keys:
        if key == "":
            return OmegaConf.to_container(given, resolve=True)
        value = OmegaConf.select(given, key, default=_ABSENT, throw_on_missing=False)
        if value is _ABSENT:
            parent, _, leaf = key.rpartition(".")
            holder = OmegaConf.select(node, parent) if parent else node
            if isinstance(holder, DictConfig) and leaf in holder:
                del holder[leaf]
            continue
        OmegaConf.update(node, key, value, merge=False, force_add=True)
    return OmegaConf.to_container(node, resolve=True)


def checkpoint_settings(ckpt: Mapping, meta: Mapping, task_cls) -> tuple[dict, str]:
    """``(settings, where from)`` of a checkpoint: the evaluation node ``lit3d-train`` saved in it, or, in
    a checkpoint saved before that node existed, the settings among its task's hyper-parameters
    (``hyper_parameters``, else the metadata's task config) over ``task_cls.evaluation_legacy``."""
    saved = meta.get(NODE)
    if isinstance(saved, Mapping):
        return dict(saved), "the checkpoint's (saved by lit3d-train)"
    moved = evaluation_legacy(task_cls)
    hp = {**(meta.get("task") or {}), **(ckpt.get("hyper_parameters") or {})}  # an upgraded checkpoint: in the task config
    settings = legacy_settings(getattr(task_cls, "__name__", "task"), {k: hp[k] for k in moved if k in hp}, moved)
    return settings, "the checkpoint's task hyper-parameters (saved before evaluation settings had their own node)"


def resolve(cfg: DictConfig, ckpt: Mapping, meta: Mapping, task_cls) -> dict:
    """The settings ``lit3d-eval`` evaluates with: the checkpoint's (:func:`checkpoint_settings`), the
    ``evaluation.*`` keys of the command line over them; logged once, naming both."""
    settings, where = checkpoint_settings(ckpt, meta, task_cls)
    keys = command_line_keys(command_line_overrides(cfg))
    if keys:
        settings = with_command_line(settings, cfg.get(NODE), keys)
        named = ", ".join(f"evaluation.{k}" if k else "evaluation" for k in keys)
        log.info("evaluation settings: %s, with %s from the command line (the command line wins)", where, named)
    else:
        log.info("evaluation settings: %s", where)
    return settings


def override_problem(args: Sequence[str], compose: Callable[[list[str]], DictConfig]) -> str | None:
    """One line for overrides that do not compose because of the evaluation node, or None (also when
    the config does not compose without the ``task.*`` and ``evaluation.*`` overrides either).
    ``compose(overrides)``: the command's config composed with those overrides.

    - ``task.KEY...`` where KEY is an evaluation setting now (a key of ``evaluation``, not of ``task``):
      the line names ``evaluation.KEY``;
    - ``evaluation.*`` where the config has no evaluation node (``lit3d-eval`` without ``task=NAME``).
    """
    from hydra.errors import HydraException

    try:
        composed_without = compose([a for a in args if not _TASK_KEY.match(a) and not _OVERRIDE.match(a)])
    except HydraException:
        return None
    task, evaluation = composed_without.get("task"), composed_without.get(NODE)
    for arg in args:
        m = _TASK_KEY.match(arg)
        if m and evaluation is not None and m.group("key") in evaluation and m.group("key") not in (task or {}):
            return moved_line(arg.split("=", 1)[0].lstrip("+~"))
        if _OVERRIDE.match(arg) and evaluation is None:
            return (f"{arg.split('=', 1)[0]}: this config has no evaluation settings; name the checkpoint's task "
                    "too (task=canonical|completion|quality): its evaluation node comes with it")
    return None


def stale_task_keys(cfg: DictConfig | None) -> str | None:
    """One line for a moved key still under ``task`` in a composed config (an experiment file or a
    ``+task.KEY=`` that still sets it there), or None."""
    task, evaluation = (cfg.get("task"), cfg.get(NODE)) if cfg is not None else (None, None)
    if not task or not evaluation:
        return None
    stale = [k for k in task if k in evaluation]
    return moved_line(f"task.{stale[0]}") if stale else None


def moved_line(key: str) -> str:
    """``task.KEY: an evaluation setting now ...: set evaluation.KEY=...``."""
    new = "evaluation." + key.split(".", 1)[1]
    return (f"{key}: an evaluation setting now, not the task's: set {new}=... instead "
            "(experiments: under evaluation:, not task:)")
