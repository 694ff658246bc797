"""Pieces shared by the Hydra entry points: config dir, task building, loggers, metadata, errors.

Heavy libraries (torch, Lightning) are imported inside the functions that need them, so
that a bad command line (unknown experiment, missing ``data.root``) is answered in about a
second instead of after ten seconds of imports.

Errors the user can act on end the process with one line on stderr (see :func:`run_cli`):

========================================================  =====  =========================================
what                                                       exit   line
========================================================  =====  =========================================
bad option/file (UserError, DataError, ShapeError, ???)    2      ``error: <file or option>: <problem>``
wrong type/range of a config value (ConfigValueError)      2      ``error: <key>=<value>: expected <what>``
unwritable output (run dir, data_dir: a file, read-only)   2      ``error: <path>: <problem>``
NaN/Inf loss (FloatingPointError)                          1      ``error: non-finite loss at ... step``
SIGTERM or Ctrl-C during training (last.ckpt saved)        143    ``error: <run dir>: stopped by SIGTERM``
SIGTERM or Ctrl-C while preparing data / evaluating        143    ``error: <data_dir|run dir>: stopped by ...``
a second one (or the first while the Anny cache builds)    130    ``error: stopped by a second SIGINT ...``
  (:mod:`lit3d.utils.forced_exit`: within 2 s)             /143
========================================================  =====  =========================================

``--debug`` on the command line or ``HYDRA_FULL_ERROR=1`` shows the traceback instead.
"""
from __future__ import annotations

import importlib
import logging
import os
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf

from lit3d.cli.about import EXIT_USER, about_flags
from lit3d.cli.compose import (  # noqa: F401  (re-exported)
    CONF_DIR, check_composes, check_group_overrides, compose_config, config_groups)
from lit3d.cli.config_checks import ConfigValueError, check_config_values, config_problem
from lit3d.cli.errors import EXIT_SIGTERM, Interrupted, UserError  # re-exported (and used here)
from lit3d.cli.key_hints import instantiation_problem
from lit3d.cli.evaluation import run_evaluation, scalar_metrics  # noqa: F401  (re-exported)
from lit3d.cli.rundir import claim_run_dir, hold_output_dir
from lit3d.utils import forced_exit, quiet
from lit3d.utils.checkpoints import first_line
from lit3d.utils.errors import Lit3dError
from lit3d.utils.io import OutputError
from lit3d.utils.stops import start_up

log = logging.getLogger("lit3d")


EXIT_DIVERGED = 1    # training stopped on a NaN/Inf loss


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
        raise (exc.__cause__ if isinstance(exc.__cause__, (ValueError, TypeError)) else exc) from exc


def _split_target(path: str) -> tuple[str, str]:
    module, _, name = path.replace(":", ".").rpartition(".")
    return LEGACY_MODULES.get(module, module), name


def build_task(task_cfg: DictConfig | dict):
    """The LightningModule of ``cfg.task``: ``hydra.utils.instantiate`` with plain arguments."""
    return _construct("task", lambda: _instantiate_plain(task_cfg))


def build_datamodule(data_cfg: DictConfig | dict):
    """Instantiate a DataModule from its config (plain values only)."""
    return _construct("data", lambda: _instantiate_plain(data_cfg))


def read_checkpoint(ckpt_path: str | Path) -> tuple[dict, dict]:
    """``(checkpoint dict, its lit3d metadata)`` (task, data config, W&B id).

    Loads with ``weights_only=True`` (see :func:`lit3d.utils.checkpoints.load_checkpoint`): a
    checkpoint that pickles arbitrary objects is refused, never executed. A canonical checkpoint comes in
    today's config layout (:func:`lit3d.canonical.checkpoint_upgrade.upgrade_checkpoint`).
    """
    from lit3d.utils.checkpoints import META_KEY, load_checkpoint

    ckpt = load_checkpoint(ckpt_path, UserError)
    meta = ckpt.get(META_KEY) if isinstance(ckpt, dict) else None
    if not isinstance(meta, dict):
        raise UserError(f"{Path(ckpt_path)}: not a lit3d checkpoint (no '{META_KEY}' metadata)")
    if (meta.get("task") or {}).get("name") == "canonical":  # maybe written before its settings were nodes
        from lit3d.canonical.checkpoint_upgrade import upgrade_checkpoint  # (imports its DataModule: only here)

        ckpt = upgrade_checkpoint(ckpt)
    return ckpt, ckpt[META_KEY]


def read_checkpoint_meta(ckpt_path: str | Path) -> dict:
    """The lit3d metadata stored in a checkpoint (:func:`read_checkpoint`)."""
    return read_checkpoint(ckpt_path)[1]


# ------------------------------------------------------------------ command line
def _debug_requested() -> bool:
    return os.environ.get("HYDRA_FULL_ERROR") == "1"


def fail(exc: BaseException, code: int) -> None:
    """Print ``error: <first line of exc>`` on stderr and exit with ``code``."""
    forced_exit.said(code)  # a second Ctrl-C while the command exits adds no second line
    print(f"error: {first_line(exc, type(exc).__name__)}", file=sys.stderr, flush=True)
    sys.exit(code)


def check_output_paths(cfg: DictConfig | None) -> None:
    """Raise :class:`UserError` (``<path>: <problem>``) before Hydra creates anything when the run
    dir (``hydra.run.dir``) is a file, lies under a file or cannot be written, or when
    ``data.data_dir`` is a file, lies under a file, or holds no prepared cache and cannot be written."""
    from lit3d.utils.io import OutputError, check_writable

    if cfg is None:
        return
    try:
        run_dir = OmegaConf.select(cfg, "hydra.run.dir", default=None)
        data_dir = OmegaConf.select(cfg, "data.data_dir", default=None)
    except Exception:  # an interpolation only Hydra's runtime can resolve: Hydra checks it
        return
    try:
        if run_dir:
            check_writable(run_dir, "hydra.run.dir")
        if data_dir:
            check_writable(data_dir, "data.data_dir", need_write=not (Path(data_dir) / "manifest.json").is_file())
    except OutputError as exc:
        raise UserError(str(exc)) from None


def cli_main(hydra_main: Callable[[], Any], argv: Sequence[str] | None = None, config_name: str = "train",
             command: str | None = None) -> Any:
    """Console-script wrapper of a ``@hydra.main`` function (whose config is ``config_name``;
    ``command``: ``train``, ``eval``, ``data`` or ``summary``, default the config's name).

    ``--version`` prints the version; ``--help`` shows the command's page (:mod:`lit3d.cli.about`).
    ``--debug`` is taken off the command line and turns on ``HYDRA_FULL_ERROR=1``
    (tracebacks); unknown config-group options (``experiment=``, ``task=``, ``data=`` ...)
    and overrides that do not compose (a misspelt key) stop with one line and exit 2 before
    Hydra runs anything. A second Ctrl-C or SIGTERM (or the first one inside a native step) ends the
    command within 2 s wherever it is (:mod:`lit3d.utils.forced_exit`).
    """
    quiet.install()
    args = about_flags(sys.argv[1:] if argv is None else argv, hydra_main)  # --version; --help: the command's page
    if "--debug" in args:
        args = [a for a in args if a != "--debug"]
        os.environ["HYDRA_FULL_ERROR"] = "1"
    with forced_exit.watching(), start_up():  # a Ctrl-C lost during the start still stops the command at its first stage
        try:
            check_group_overrides(args)
            composed = check_composes(args, config_name)
            check_config_values(composed)  # types and ranges (lit3d.cli.config_checks)
            check_output_paths(composed)
            args, run_dir_lock = claim_run_dir(composed, args, command or config_name)  # one process per run dir
        except (UserError, ConfigValueError, OutputError) as exc:
            if _debug_requested():
                raise
            fail(exc, EXIT_USER)
        except KeyboardInterrupt:
            stopped_early()
        sys.argv = [sys.argv[0], *args]
        try:
            with run_dir_lock:
                return hydra_main()
        except KeyboardInterrupt:  # in Hydra's start, before run_cli
            stopped_early()


def stopped_early() -> None:
    """A Ctrl-C where no stage of the command handles it (while it starts, imports or builds its model):
    one line and exit 143 instead of Python's traceback (``--debug``: the traceback). What earlier stages
    finished stays (prepared data items, checkpoints); nothing is half-written (every write is atomic)."""
    if _debug_requested():
        raise KeyboardInterrupt
    fail(UserError("stopped by SIGINT (Ctrl-C) before the command's work began or between its stages; files it "
                   "had finished are kept; the same command again starts over"), EXIT_SIGTERM)


def exit_code_for(exc: BaseException) -> int | None:
    """Exit status for an exception that ends as one line, or None (let it propagate)."""
    from omegaconf.errors import MissingMandatoryValue

    from datamodules.cache import DataError
    from lit3d.render.convert import ShapeError

    if isinstance(exc, Interrupted):
        return exc.exit_code
    if isinstance(exc, (UserError, ConfigValueError, DataError, ShapeError, MissingMandatoryValue)):
        return EXIT_USER
    if _file_system_fault(exc):  # an output that cannot be written: the path and the problem
        return EXIT_USER
    if isinstance(exc, FloatingPointError):  # NaN/Inf loss: the message names the step and the term
        return EXIT_DIVERGED
    return None


def _file_system_fault(exc: BaseException) -> bool:
    """An OSError of a path the user chose: read-only, no permission, no space, a file where a
    folder should be (or the reverse)."""
    import errno

    from lit3d.utils.io import OutputError

    return isinstance(exc, OutputError) or (isinstance(exc, OSError) and exc.filename is not None and exc.errno in (
        errno.EROFS, errno.EACCES, errno.EPERM, errno.ENOSPC, errno.EDQUOT, errno.ENOTDIR, errno.EISDIR,
        errno.EEXIST))


def _as_user_error(exc: BaseException) -> BaseException:
    """A file-system OSError as ``UserError("<path>: cannot write here (<problem>)")``."""
    from lit3d.utils.io import OutputError, output_error

    if isinstance(exc, OSError) and not isinstance(exc, OutputError) and _file_system_fault(exc):
        return UserError(str(output_error(exc.filename, exc)))
    return exc


LIGHTNING_LOGGERS = ("lightning", "lightning.pytorch", "lightning.fabric")


def log_once_through_hydra() -> None:
    """Lightning gives its loggers their own stderr handlers when it is imported; under Hydra, which
    has already configured the root logger, every Lightning line then appears twice (once bare, once in
    Hydra's format). Drop Lightning's handlers and let its records reach Hydra's root handlers."""
    import lightning.pytorch  # noqa: F401  (its import adds the handlers we remove)

    for name in LIGHTNING_LOGGERS:
        logger = logging.getLogger(name)
        for handler in list(logger.handlers):
            logger.removeHandler(handler)
        logger.propagate = True


def run_cli(fn: Callable[[DictConfig], Any], cfg: DictConfig) -> Any:
    """Run ``fn(cfg)``; errors the user can act on become one line on stderr (see module doc).

    ``HYDRA_FULL_ERROR=1`` (or ``--debug``) shows the traceback instead.
    """
    from omegaconf.errors import MissingMandatoryValue

    quiet.install()  # again here: a submitit job process runs this, not cli_main
    try:
        missing = sorted(OmegaConf.missing_keys(cfg))
        if missing:  # before any work or logging: the one line is all the user sees
            raise UserError(f"missing value for {missing[0]}: set {missing[0]}=... on the command line")
        check_config_values(cfg)  # again here: a multirun job's values are not composed by cli_main
        log_once_through_hydra()  # imports Lightning: only once the command line is known to be whole
        with hold_output_dir(cfg):  # a multirun job's dir; a no-op where cli_main holds the run dir
            return fn(cfg)
    except KeyboardInterrupt:  # the stages with their own stop (data, training, evaluation) raise Interrupted
        stopped_early()
    except Exception as exc:
        code = exit_code_for(exc)
        refused = instantiation_problem(exc) if code is None else None
        if refused and not _debug_requested():  # +trainer.max_epoch=3: the Trainer has no such argument
            fail(UserError(refused), EXIT_USER)
        if code is None or _debug_requested():
            raise
        if isinstance(exc, MissingMandatoryValue):
            key = getattr(exc, "full_key", "") or "a required option"
            exc = UserError(f"missing value for {key}: set {key}=... on the command line")
        fail(_as_user_error(exc), code)

