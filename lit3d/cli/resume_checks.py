"""A checkpoint against the config that resumes from it (``lit3d-train ckpt_path=...``) or evaluates
it (``lit3d-eval ckpt_path=... data=...``), before any work. Each refusal is one line
(:class:`~lit3d.runtime.errors.UserError`, exit 2); docs/resuming.md "Resume checks".

- :func:`check_task_matches`: the checkpoint holds this config's task (``task_info.name`` and the
  LightningModule class), else ``<ckpt>: the checkpoint holds the canonical task (...), this
  config the completion task (...)``.
- :func:`check_resume_config`: the data and the architecture (:data:`COMPARED`: ``data.*``,
  ``task.net(s)``, ``task.arch`` ...) are the checkpoint's, unless ``+resume.allow_changes=true``;
  the other keys (``trainer.max_epochs``, logging, learning rates ...) may differ and are logged.
  The run dir's ``config.yaml``, which a resume never reads, is refused when it was edited (it
  holds data or architecture values of neither the checkpoint nor this run).
- :func:`check_weights_fit`: the checkpoint's weights fit the nets this config builds (a changed
  architecture taken with ``allow_changes`` still has to fit).
- :func:`check_eval_data`: ``lit3d-eval``'s ``data=`` is data of the checkpoint's task.
"""
from __future__ import annotations

import logging
from fnmatch import fnmatchcase
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf

from lit3d.runtime.build import LEGACY_MODULES, task_meta, to_plain
from lit3d.runtime.errors import UserError
from lit3d.runtime.registry import EVALUATORS

log = logging.getLogger("lit3d")

ALLOW_KEY = "resume.allow_changes"
# what a resume must keep from the checkpoint (dotted keys of cfg.task / cfg.data; fnmatch patterns)
COMPARED = ("data.*", "task._target_", "task.arch", "task.net", "task.net.*", "task.nets", "task.nets.*",
            "task.net.lfe.use", "task.net.msfe.use", "task.features", "task.identity.classes")
# data keys that change how the data is loaded or where it lies, not which items it holds
LOADING = ("data.num_workers", "data.pin_memory", "data.prepare.progress", "data.prepare_workers", "data.prepare.workers",
           "data.feature_tables.workers", "data.persistent_workers", "data.data_dir")
TASK_INFO = ("name", "monitor", "monitor_mode")  # task_meta() puts cfg.task_info beside cfg.task


def compared(key: str) -> bool:
    """A key a resume must keep (data or architecture), see :data:`COMPARED`."""
    return any(fnmatchcase(key, p) for p in COMPARED) and not any(fnmatchcase(key, p) for p in LOADING)


def differences(old: Any, new: Any, prefix: str) -> list[tuple[str, Any, Any]]:
    """``(dotted key, old, new)`` where two plain configs differ; keys on one side only (options
    added or removed by another lit3d version) are not compared; lists compare whole."""
    if isinstance(old, dict) and isinstance(new, dict):
        out = []
        for k in old.keys() & new.keys():
            out += differences(old[k], new[k], f"{prefix}.{k}")
        return sorted(out, key=lambda d: d[0])
    return [] if _same(old, new) else [(prefix, old, new)]


def _same(a: Any, b: Any) -> bool:
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    if isinstance(a, bool) or isinstance(b, bool):
        return a is b
    return a == b


def _show(value: Any, width: int = 40) -> str:
    text = "null" if value is None else str(value).lower() if isinstance(value, bool) else str(value)
    return text if len(text) <= width else text[: width - 3] + "..."


def _listing(diffs: list[tuple[str, Any, Any]], there: str, here: str) -> str:
    return ", ".join(f"{k}: {_show(a)} {there}, {_show(b)} {here}" for k, a, b in diffs)


def _sections(task: dict, data: dict) -> dict:
    """``{"task": ..., "data": ...}`` of a checkpoint's metadata (task_info keys left out)."""
    return {"task": {k: v for k, v in (task or {}).items() if k not in TASK_INFO}, "data": dict(data or {})}


def _module_path(target: str) -> str:
    module, _, name = str(target).replace(":", ".").rpartition(".")
    return f"{LEGACY_MODULES.get(module, module)}.{name}"


def check_task_matches(ckpt_path: str | Path, meta: dict, cfg: DictConfig) -> None:
    """Refuse a checkpoint of another task than ``cfg``'s (name or LightningModule class)."""
    have = meta.get("task") or {}
    have_name, have_target = have.get("name"), have.get("_target_")
    want_name = OmegaConf.select(cfg, "task_info.name", default=None)
    want_target = OmegaConf.select(cfg, "task._target_", default=None)
    have_cls, want_cls = _module_path(have_target or "?"), _module_path(want_target or "?")
    other_name = bool(have_name and want_name) and have_name != want_name
    other_cls = bool(have_target and want_target) and have_cls != want_cls
    if other_name or other_cls:
        raise UserError(f"{ckpt_path}: the checkpoint holds the {have_name or '?'} task ({have_cls}), this config "
                        f"the {want_name or '?'} task ({want_cls}); resume a checkpoint of this task, or choose the "
                        f"checkpoint's task (task={have_name} or its experiment=...)")


def check_resume_config(ckpt_path: str | Path, meta: dict, cfg: DictConfig, run_dir: Path) -> None:
    """Refuse a resume whose data or architecture differs from the checkpoint's (unless
    ``+resume.allow_changes=true``), and a hand-edited ``<run_dir>/config.yaml``; log the other changes."""
    check_task_matches(ckpt_path, meta, cfg)
    saved = _sections(meta.get("task"), meta.get("data"))
    now = _sections(task_meta(cfg), to_plain(cfg.get("data")))
    diffs = [d for s in ("task", "data") for d in differences(saved[s], now[s], s)]
    strict = [d for d in diffs if compared(d[0])]
    allow = bool(OmegaConf.select(cfg, ALLOW_KEY, default=False))
    if strict and not allow:
        raise UserError(f"{ckpt_path}: this run's data or architecture differs from the checkpoint's "
                        f"({_listing(strict, 'in the checkpoint', 'here')}); resume with the checkpoint's values, or "
                        f"add +{ALLOW_KEY}=true to take the changes")
    if diffs:
        log.info("resuming %s with changes: %s", ckpt_path, _listing(diffs, "before", "now"))
    _check_run_dir_config(run_dir / "config.yaml", saved, now)


def _check_run_dir_config(path: Path, saved: dict, now: dict) -> None:
    """A ``config.yaml`` whose data/architecture values are neither the checkpoint's nor this run's was
    edited by hand: a resume never reads it, and writing this run's config would lose the edit."""
    if not path.is_file():
        return
    try:
        old = OmegaConf.to_container(OmegaConf.load(path), resolve=False)
    except Exception:  # unreadable: nothing to lose that a user could mean to keep
        return
    if not isinstance(old, dict):
        return
    file = _sections(old.get("task"), old.get("data"))
    # differs from this run and from the checkpoint: not a config this run or the checkpoint's run wrote
    edited = [(k, a, b) for s in ("task", "data") for k, a, b in differences(file[s], now[s], s)
              if compared(k) and _differs_from(saved, k, a)]
    if edited:
        listing = _listing(edited, "in config.yaml", "in this run")
        raise UserError(f"{path}: edited since the checkpoint was saved ({listing}); a resume takes its config "
                        f"from the command line, not from config.yaml: give the changes "
                        f"as overrides (with +{ALLOW_KEY}=true), or undo the edit")


def _differs_from(saved: dict, key: str, value: Any) -> bool:
    """``saved`` records ``key`` with another value than ``value``."""
    node: Any = saved
    for part in key.split("."):
        if not isinstance(node, dict) or part not in node:
            return False  # not recorded in the checkpoint: cannot tell an edit from another version
        node = node[part]
    return not _same(node, value)


def check_weights_fit(ckpt_path: str | Path, task, state: dict) -> None:
    """Refuse a checkpoint (named ``ckpt_path``, its ``state_dict`` ``state``) whose weights do not fit
    ``task``'s nets (another size or layout) before any data is prepared, instead of Lightning's
    ``Error(s) in loading state_dict`` traceback.

    Compared: the shapes of the entries both have; the parameters of ``task`` the checkpoint lacks;
    the entries of the checkpoint ``task`` lacks. A module whose nets are built only when a
    checkpoint is loaded (an empty state dict) is left to its own ``on_load_checkpoint``."""
    own = task.state_dict()
    if not own:
        return
    problems = [f"{k}: {tuple(state[k].shape)} in the checkpoint, {tuple(v.shape)} here"
                for k, v in own.items() if k in state and tuple(getattr(state[k], "shape", ())) != tuple(v.shape)]
    problems += [f"{k}: not in the checkpoint" for k, _ in task.named_parameters() if k not in state]
    problems += [f"{k}: not in this config's nets" for k in state if k not in own]
    if problems:
        more = f"; {len(problems) - 2} more" if len(problems) > 2 else ""
        raise UserError(f"{ckpt_path}: the checkpoint's weights do not fit the nets of this config "
                        f"({'; '.join(problems[:2])}{more}); the checkpoint holds another architecture: resume "
                        f"with its task.net(s) sizes, or start a new run")


def data_task(data_cfg: dict | DictConfig | None) -> str | None:
    """The task a data config is for, from its DataModule's package (``datamodules.<task>....``)."""
    target = str((data_cfg or {}).get("_target_", ""))
    parts = target.split(".")
    return parts[1] if len(parts) > 2 and parts[0] == "datamodules" and parts[1] in EVALUATORS else None


def check_eval_data(ckpt_path: str | Path, meta: dict, data_cfg: dict | DictConfig | None) -> None:
    """Refuse ``lit3d-eval`` of a checkpoint with data of another task (``data=completion_synth``
    for a canonical checkpoint) before the data is touched."""
    have = (meta.get("task") or {}).get("name")
    wanted = data_task(data_cfg)
    if data_cfg is None or have is None or wanted is None or wanted == have:
        return
    target = str(data_cfg.get("_target_"))
    cls = _module_path((meta.get("task") or {}).get("_target_", "?"))
    raise UserError(f"{ckpt_path}: the checkpoint holds the {have} task ({cls}), the data config is for the "
                    f"{wanted} task ({target}); choose data of the {have} task (data=NAME), or leave data out "
                    f"to evaluate on the checkpoint's own data")
