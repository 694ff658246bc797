"""What the lit3d commands say about themselves: ``--version``, and each Hydra entry point's help page.

``--help`` (``-h``) of ``lit3d-train``, ``lit3d-eval``, ``lit3d-data`` and ``lit3d-summary`` shows the
page ``conf/hydra/help/<page>.yaml`` of that command (Hydra's ``hydra/help`` template: what the
command does, three examples, its groups and main keys) instead of Hydra's default ("... is powered by
Hydra" and the whole composed config). ``--version`` prints ``<command> (lit3d) <version>``; the
argparse commands (``lit3d-score``, ``lit3d-reconstruct``) use :func:`version_line` too.
"""
from __future__ import annotations

import inspect
import re
import signal
import sys
import threading
from collections.abc import Callable, Sequence
from pathlib import Path

from lit3d.utils.checkpoints import first_line
from lit3d.utils.extras import MissingExtra
from lit3d.utils.provenance import lit3d_version

EXIT_USER = 2        # a problem with the command line, a config or an input file

# entry-point module -> (command, help page in conf/hydra/help/)
COMMANDS = {
    "train": ("lit3d-train", "train"),
    "evaluate": ("lit3d-eval", "evaluate"),
    "data": ("lit3d-data", "data"),
    "summary": ("lit3d-summary", "summary"),
}
HELP_FLAGS = ("--help", "-h")


def version_line(command: str) -> str:
    return f"{command} (lit3d) {lit3d_version()}"


def command_of(hydra_main: Callable) -> tuple[str, str]:
    """``(command, help page)`` of a ``@hydra.main`` function, from its module (``lit3d.cli.train`` ...)."""
    module = getattr(hydra_main, "__module__", "") or ""
    if module == "__main__":  # python -m lit3d.cli.<name>: the file of the undecorated function
        module = Path(inspect.unwrap(hydra_main).__code__.co_filename).stem
    return COMMANDS.get(module.rsplit(".", 1)[-1], ("lit3d", "train"))


def about_flags(args: Sequence[str], hydra_main: Callable) -> list[str]:
    """``--version``: print :func:`version_line` and exit 0. ``--help``/``-h``: the arguments plus the
    override that picks the command's help page. Other arguments are returned unchanged."""
    command, page = command_of(hydra_main)
    args = list(args)
    if "--version" in args:
        print(version_line(command))
        sys.exit(0)
    if any(a in HELP_FLAGS for a in args):
        args.append(f"hydra/help={page}")
    return args


# NotImplementedError: an input format or option the command does not take; MissingExtra: an option whose
# optional extra is not installed (lit3d.utils.extras)
USER_ERRORS = (ValueError, FileNotFoundError, PermissionError, NotImplementedError, MissingExtra)


def allocation_failure(exc: BaseException) -> str | None:
    """``"not enough memory (tried to allocate 2.25 GiB)"`` for an allocation that failed (a
    ``MemoryError``, numpy's included, or torch's "can't allocate memory" / "out of memory"
    ``RuntimeError``); None for any other error. A resource limit, not a bug: exit 2."""
    text = str(exc)
    if not isinstance(exc, MemoryError) and not (
            isinstance(exc, RuntimeError) and re.search(r"can't allocate memory|out of memory", text, re.I)):
        return None
    size = None
    if m := re.search(r"allocate (\d+) bytes", text):  # torch on CPU
        n, units = float(m.group(1)), ["bytes", "KiB", "MiB", "GiB", "TiB", "PiB"]
        while n >= 1024 and len(units) > 1:
            n, units = n / 1024, units[1:]
        size = f"{n:.2f} {units[0]}"
    elif m := re.search(r"allocate ([\d.]+ [KMGTP]i?B)", text, re.I):
        size = m.group(1)
    return "not enough memory" + (f" (tried to allocate {size})" if size else "")


def report_error(prog: str, exc: Exception, prefix: str = "") -> int:
    """One line ``PROG: error: ...`` (a user error: bad input or a resource limit such as memory,
    exit 2) or ``PROG: internal error (...)`` (exit 1) on stderr; returns the exit status."""
    memory = allocation_failure(exc)
    user = memory is not None or isinstance(exc, USER_ERRORS)
    kind = "error" if user else f"internal error ({type(exc).__name__}; rerun with --debug)"
    print(f"{prog}: {kind}: {prefix}{memory or first_line(exc, type(exc).__name__)}", file=sys.stderr, flush=True)
    return EXIT_USER if user else 1


class Stopped(KeyboardInterrupt):
    """A stop by a signal inside an argparse CLI: SIGTERM (raised by :func:`run_argparse_cli`'s
    handler) or Ctrl-C. A ``KeyboardInterrupt``, so what finishes a set of files on Ctrl-C
    (:func:`lit3d.utils.io.write_file_set`) finishes it on SIGTERM too. ``detail``: what the
    command kept, said on its stop line."""

    def __init__(self, signame: str = "SIGINT", detail: str = ""):
        super().__init__(signame)
        self.signame, self.detail = signame, detail

    @property
    def exit_code(self) -> int:
        return 128 + int(getattr(signal, self.signame))  # 130 for SIGINT, 143 for SIGTERM

    def line(self, prog: str) -> str:
        what = "interrupted" if self.signame == "SIGINT" else f"stopped by {self.signame}"
        return f"{prog}: {what}" + (f" {self.detail}" if self.detail else "")


def _raise_stopped(signum, _frame) -> None:
    raise Stopped(signal.Signals(signum).name)


def run_argparse_cli(prog: str, parser, run: Callable, argv: Sequence[str] | None = None) -> int:
    """The argparse CLIs' ``main``: quiet third-party output, parse, ``run(args)``; Ctrl-C exits 130
    and SIGTERM 143, each with one line (:class:`Stopped`); any other error is
    :func:`report_error`'s line (``--debug``: the traceback). A second Ctrl-C or SIGTERM (or the first
    one inside a native step) ends the command within 2 s wherever it is (:mod:`lit3d.utils.forced_exit`)."""
    from lit3d.utils import forced_exit, quiet

    quiet.install()
    args = parser.parse_args(argv)
    main_thread = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGTERM, _raise_stopped) if main_thread else None
    try:
        with forced_exit.watching(f"{prog}: "):
            try:
                return run(args)
            except KeyboardInterrupt as exc:
                stop = exc if isinstance(exc, Stopped) else Stopped("SIGINT")
                forced_exit.said(stop.exit_code)
                print(stop.line(prog), file=sys.stderr, flush=True)
                return stop.exit_code
            except Exception as exc:
                if args.debug:
                    raise
                code = report_error(prog, exc)
                forced_exit.said(code)
                return code
    finally:
        if main_thread:  # None: the earlier handler was not set from Python
            signal.signal(signal.SIGTERM, signal.SIG_DFL if previous is None else previous)
