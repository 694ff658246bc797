"""The Hydra commands' checks that a command line's choices have their optional extras installed
(:mod:`lit3d.utils.extras`), before Hydra starts or creates a run dir:

- ``hydra/launcher=slurm|slurm_local`` needs ``lit3d[slurm]``, ``hparams_search=NAME`` (and
  ``hydra/sweeper=optuna``) ``lit3d[optuna]``: without them Hydra cannot even compose the config;
- ``logger=wandb`` / ``logger=tensorboard`` (``lit3d-train``) need ``lit3d[wandb]`` / ``lit3d[tensorboard]``;
- the Anny data (``data.source.kind=anny``: ``data=anny``, ``experiment=canonical_humans``) and the body
  regressor task (``task_info.name=body``: ``experiment=body_regressor``) need ``lit3d[body]``.

``lit3d-train``'s default logger is W&B (offline); where ``wandb`` is not installed and the command line
picks no logger, :func:`default_logger` picks ``logger=none`` (the CSV log every run keeps) and the
command says so once every check has passed.
"""
from __future__ import annotations

from collections.abc import Sequence

from omegaconf import DictConfig, OmegaConf

from lit3d.utils.extras import has_extra, require

# the loggers' classes (a logger node's _target_ ends with one) -> (the extra, the logger option)
LOGGER_EXTRAS = {"WandbLogger": ("wandb", "logger=wandb"), "TensorBoardLogger": ("tensorboard", "logger=tensorboard")}
HYDRA_BUILT_IN = ("basic", "", "null")  # Hydra's own launcher and sweeper


def _key_value(arg: str) -> tuple[str, str]:
    key, _, value = arg.partition("=")
    return key.lstrip("+~"), value


def check_override_extras(args: Sequence[str]) -> None:
    """Raise :class:`~lit3d.utils.extras.MissingExtra` for a launcher or sweeper on the command line
    whose Hydra plugin is not installed (Hydra's own answer would be "Could not find
    'hydra/launcher/submitit_slurm'")."""
    for arg in args:
        key, value = _key_value(arg)
        if "=" not in arg or value in HYDRA_BUILT_IN:
            continue
        if key == "hydra/launcher":
            require("slurm", arg)
        elif key in ("hydra/sweeper", "hparams_search"):  # every hparams_search config uses the Optuna sweeper
            require("optuna", arg)


def check_logger_extras(cfg: DictConfig | None) -> None:
    """Raise :class:`~lit3d.utils.extras.MissingExtra` when a logger of ``cfg.logger`` needs an extra
    that is not installed."""
    loggers = OmegaConf.select(cfg, "logger", default=None) if cfg is not None else None
    for node in (loggers or {}).values():
        target = str((node or {}).get("_target_", ""))
        for cls, (extra, what) in LOGGER_EXTRAS.items():
            if target.endswith(cls):
                require(extra, what)


def check_data_extras(cfg: DictConfig | None, args: Sequence[str] = ()) -> None:
    """Raise :class:`~lit3d.utils.extras.MissingExtra` when ``cfg.data`` uses the Anny body model (the
    canonical task's Anny source, or the body task) and ``lit3d[body]`` is not installed (the line names
    the experiment that chose it, unless the command line ``args`` chose the data)."""
    if cfg is None:
        return
    experiment = OmegaConf.select(cfg, "hydra.runtime.choices.experiment", default=None)
    if OmegaConf.select(cfg, "task_info.name", default=None) == "body":
        require("body", f"experiment={experiment} (the body task)" if experiment else "task=body")
        return
    if OmegaConf.select(cfg, "data.source.kind", default=None) != "anny":
        return
    by_experiment = experiment and not any(_key_value(a)[0].split(".")[0] == "data" for a in args)
    require("body", f"experiment={experiment} (data.source.kind=anny)" if by_experiment else "data.source.kind=anny")


NO_WANDB_NOTE = ("wandb is not installed: logging to the CSV log only (logger=none); "
                 "pip install 'lit3d[wandb]' for the offline W&B log")


def default_logger(args: Sequence[str], composed: DictConfig | None) -> tuple[list[str], str | None]:
    """``(args plus logger=none, the note saying so)`` when the logger would be the default W&B one and
    ``wandb`` is not installed (``pip install lit3d`` without ``[wandb]``); else ``(args, None)``.

    A logger on the command line is kept (and checked by :func:`check_logger_extras`). ``composed``: the
    config of ``args``; None where :func:`~lit3d.runtime.compose.check_composes` composes nothing (Hydra's flags):
    then only a multirun (``-m``) gets ``logger=none``, the others (``--help``, ``--cfg job`` ...) run nothing.
    """
    args = list(args)
    if has_extra("wandb") or any(_key_value(a)[0] == "logger" for a in args):
        return args, None
    if composed is None and not any(a in ("-m", "--multirun") for a in args):
        return args, None
    if composed is not None and OmegaConf.select(composed, "hydra.runtime.choices.logger", default=None) != "wandb":
        return args, None
    return [*args, "logger=none"], NO_WANDB_NOTE
