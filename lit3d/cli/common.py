"""Pieces shared by the console scripts: the Hydra entry (:func:`cli_main`, :func:`run_cli`), exit codes and
one-line errors. Config composition, task building and checkpoint reading are the runtime's (:mod:`lit3d.runtime`).

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
an option whose optional extra is missing (MissingExtra)   2      ``error: <option> needs <what>: pip install 'lit3d[<extra>]'``
NaN/Inf loss (FloatingPointError)                          1      ``error: non-finite loss at ... step``
SIGTERM or Ctrl-C during training (last.ckpt saved)        143    ``error: <run dir>: stopped by SIGTERM``
SIGTERM or Ctrl-C while preparing data / evaluating        143    ``error: <data_dir|run dir>: stopped by ...``
a second one (or the first while the Anny cache builds)    130    ``error: stopped by a second SIGINT ...``
  (:mod:`lit3d.utils.forced_exit`: within 2 s)             /143
========================================================  =====  =========================================

``--debug`` on the command line or ``HYDRA_FULL_ERROR=1`` shows the traceback instead.
"""
from __future__ import annotations

import logging
import os
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf

from lit3d.cli.about import EXIT_USER, about_flags
from lit3d.runtime.compose import check_composes, check_group_overrides
from lit3d.runtime.config_checks import ConfigValueError, check_config_values
from lit3d.runtime.errors import EXIT_SIGTERM, Interrupted, UserError
from lit3d.runtime.key_hints import instantiation_problem
from lit3d.runtime.extra_checks import check_data_extras, check_logger_extras, check_override_extras, default_logger
from lit3d.cli.rundir import claim_run_dir, hold_output_dir
from lit3d.utils import forced_exit, quiet
from lit3d.utils.checkpoints import first_line
from lit3d.utils.extras import MissingExtra
from lit3d.utils.io import OutputError
from lit3d.utils.stops import start_up

log = logging.getLogger("lit3d")


EXIT_DIVERGED = 1    # training stopped on a NaN/Inf loss


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
    Hydra runs anything, as does a choice whose optional extra is not installed (:mod:`lit3d.runtime.extra_checks`;
    ``lit3d-train`` without ``wandb`` and no ``logger=``: ``logger=none``). A second Ctrl-C or SIGTERM (or the first one
    inside a native step) ends the command within 2 s wherever it is (:mod:`lit3d.utils.forced_exit`).
    """
    quiet.install()
    args = about_flags(sys.argv[1:] if argv is None else argv, hydra_main)  # --version; --help: the command's page
    if "--debug" in args:
        args = [a for a in args if a != "--debug"]
        os.environ["HYDRA_FULL_ERROR"] = "1"
    with forced_exit.watching(), start_up():  # a Ctrl-C lost during the start still stops the command at its first stage
        try:
            check_group_overrides(args)
            check_override_extras(args)  # a launcher or sweeper plugin that is not installed: before Hydra composes
            composed = check_composes(args, config_name)
            check_data_extras(composed, args)
            note = None
            if (command or config_name) == "train":  # the loggers are lit3d-train's
                args, note = default_logger(args, composed)
                if note is not None:
                    composed = check_composes(args, config_name)
                check_logger_extras(composed)
            check_config_values(composed)  # types and ranges (lit3d.runtime.config_checks)
            check_output_paths(composed)
            args, run_dir_lock = claim_run_dir(composed, args, command or config_name)  # one process per run dir
            if note is not None:  # after every check: a refused command line stays one line
                print(f"note: {note}", file=sys.stderr, flush=True)
        except (UserError, ConfigValueError, OutputError, MissingExtra) as exc:
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
    if isinstance(exc, (UserError, ConfigValueError, DataError, ShapeError, MissingMandatoryValue, MissingExtra)):
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

