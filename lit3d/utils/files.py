"""One wording, for every command, of an input path that is not the regular file it should be.

:func:`path_problem` names what the path is instead: ``no such file`` (missing),
``broken symbolic link (to X)``, ``a folder, not a file``, ``a named pipe (FIFO), not a regular
file`` (also a socket or a device: never opened, a read could block), ``cannot read it (...)``.
``lit3d-reconstruct`` (depth images, masks), ``lit3d-score`` (shapes, ``--pairs`` files and the
files they name), the checkpoint readers and the Python API raise their own error class with
``<path>: <problem>`` built from it.
"""
from __future__ import annotations

import os
import stat
from pathlib import Path

_NOT_REGULAR = ((stat.S_ISFIFO, "a named pipe (FIFO)"), (stat.S_ISSOCK, "a socket"),
                (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"))


def path_problem(path: str | os.PathLike, what: str = "file") -> str | None:
    """None when ``path`` is a regular file (or a link to one), else what it is (see the module doc;
    ``what`` names the file: ``no such mask file``, ``a folder, not a mask file``). Only ``stat``
    is called: a FIFO is never opened."""
    p = Path(path)
    try:
        mode = p.stat().st_mode
    except FileNotFoundError:
        return f"broken symbolic link (to {os.readlink(p)})" if p.is_symlink() else f"no such {what}"
    except OSError as exc:
        return f"cannot read it ({exc.strerror or type(exc).__name__})"
    if stat.S_ISDIR(mode):
        return f"a folder, not a {what}"
    if stat.S_ISREG(mode):
        return None
    kind = next((name for test, name in _NOT_REGULAR if test(mode)), "not a file")
    return f"{kind}, not a regular {what}"


def shown(path: str | os.PathLike) -> str:
    """``path`` as printable text: bytes of a name that are not UTF-8 (a Latin-1 ``caf\\xe9.obj``, read
    with ``surrogateescape``) as ``\\xNN`` escapes, so that printing it never fails."""
    return str(path).encode("utf-8", "surrogateescape").decode("utf-8", "backslashreplace")
