"""Whole-process locks on a folder: ``flock`` on a lock file that names its holder.

:func:`hold` takes the exclusive lock of a lock file and writes the holder into it (``pid N on
HOST since YYYY-MM-DD HH:MM:SS``); a second process is refused with :class:`LockBusy` naming
that holder, or waits for it (``wait=True``). The system releases the lock when the holder
exits, however it exits (SIGKILL included), so a lock is never stale: a leftover lock file of
a dead process is simply taken. Where ``fcntl`` or the file system's locks are missing, a
warning is logged and no lock is taken.
"""
from __future__ import annotations

import logging
import os
import socket
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import IO

from lit3d.utils.io import OutputError

try:
    import fcntl
except ImportError:  # pragma: no cover - not POSIX
    fcntl = None

log = logging.getLogger("lit3d")

__all__ = ["HeldLock", "LockBusy", "hold", "holder_line"]


class LockBusy(OutputError):
    """Another process holds the lock: ``<folder>: <what> in use by pid N on HOST since T; <advice>``."""


def holder_line() -> str:
    """``pid N on HOST since YYYY-MM-DD HH:MM:SS``: this process, as a lock file names it."""
    return f"pid {os.getpid()} on {socket.gethostname()} since {time.strftime('%Y-%m-%d %H:%M:%S')}"


class HeldLock:
    """A lock this process took (:func:`hold`); ``release()`` or leaving a ``with`` block frees it.
    A lock this process already held is given as a no-op ``HeldLock`` (``owner=False``)."""

    def __init__(self, path: Path, file: IO | None, owner: bool):
        self.path, self._file, self.owner = path, file, owner
        self.waited = False  # set by the caller that waited for it (lit3d.cli.rundir.lock_run_dir)

    def release(self) -> None:
        if not self.owner or self._file is None:
            return
        with _GUARD:
            _HELD.pop(str(self.path), None)
        try:
            self._file.seek(0)
            self._file.truncate()  # no holder any more
            self._file.flush()
            fcntl.flock(self._file.fileno(), fcntl.LOCK_UN)
        except OSError:
            pass
        finally:
            self._file.close()
            self._file = None

    def __enter__(self) -> HeldLock:
        return self

    def __exit__(self, *exc) -> None:
        self.release()


_HELD: dict[str, HeldLock] = {}  # lock file -> the lock this process holds on it
_GUARD = threading.Lock()


def hold(path: str | os.PathLike, busy: Callable[[str], str], wait: bool = False,
         on_wait: Callable[[str], None] | None = None) -> HeldLock:
    """Take the exclusive lock of the lock file ``path`` (created when missing) and name this
    process in it. Held by this process already: a no-op :class:`HeldLock`. Held by another:
    raise :class:`LockBusy` with ``busy(holder)`` as the message, or, with ``wait``, call
    ``on_wait(holder)`` once and block until the holder lets go."""
    path = Path(path).resolve()
    with _GUARD:
        if str(path) in _HELD:
            return HeldLock(path, None, owner=False)
    if fcntl is None:  # pragma: no cover - not POSIX
        log.warning("%s: no fcntl here: going on without the lock", path)
        return HeldLock(path, None, owner=False)
    f = open(path, "a+")  # kept open while the lock is held
    try:
        try:
            fcntl.flock(f.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            f.seek(0)
            holder = f.read().strip() or "another process"
            if not wait:
                raise LockBusy(busy(holder)) from None
            if on_wait is not None:
                on_wait(holder)
            fcntl.flock(f.fileno(), fcntl.LOCK_EX)
        except OSError as exc:  # e.g. ENOLCK on some network file systems
            log.warning("%s: cannot lock (%s): going on without the lock", path, exc)
            f.close()
            return HeldLock(path, None, owner=False)
        f.seek(0)
        f.truncate()
        f.write(holder_line() + "\n")
        f.flush()
    except BaseException:
        f.close()
        raise
    lock = HeldLock(path, f, owner=True)
    with _GUARD:
        _HELD[str(path)] = lock
    return lock
