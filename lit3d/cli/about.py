"""What the lit3d commands say about themselves: ``--version``, and each Hydra entry point's help page.

``--help`` (``-h``) of ``lit3d-train``, ``lit3d-eval``, ``lit3d-data`` and ``lit3d-summary`` shows the
page ``conf/hydra/help/<page>.yaml`` of that command (Hydra's ``hydra/help`` template: what the
command does, three examples, its groups and main keys) instead of Hydra's default ("... is powered by
Hydra" and the whole composed config). ``--version`` prints ``<command> (lit3d) <version>``; the
argparse commands (``lit3d-score``, ``lit3d-reconstruct``) use :func:`version_line` too.
"""
from __future__ import annotations

import inspect
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

from lit3d.utils.provenance import lit3d_version

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


# NotImplementedError: an input format or option the command does not take
USER_ERRORS = (ValueError, FileNotFoundError, PermissionError, NotImplementedError)


def report_error(prog: str, exc: Exception, prefix: str = "") -> int:
    """One line ``PROG: error: ...`` (a user error: bad input, exit 2) or ``PROG: internal error (...)``
    (exit 1) on stderr; returns the exit status."""
    from lit3d.cli.common import EXIT_USER
    from lit3d.utils.checkpoints import first_line

    user = isinstance(exc, USER_ERRORS)
    kind = "error" if user else f"internal error ({type(exc).__name__}; rerun with --debug)"
    print(f"{prog}: {kind}: {prefix}{first_line(exc, type(exc).__name__)}", file=sys.stderr, flush=True)
    return EXIT_USER if user else 1


def run_argparse_cli(prog: str, parser, run: Callable, argv: Sequence[str] | None = None) -> int:
    """The argparse CLIs' ``main``: quiet third-party output, parse, ``run(args)``; Ctrl-C exits 130
    with one line, any other error is :func:`report_error`'s line (``--debug``: the traceback)."""
    from lit3d.utils import quiet

    quiet.install()
    args = parser.parse_args(argv)
    try:
        return run(args)
    except KeyboardInterrupt:
        print(f"{prog}: interrupted", file=sys.stderr, flush=True)
        return 130
    except Exception as exc:
        if args.debug:
            raise
        return report_error(prog, exc)
