"""The inter-process lock of a cache folder (``flock`` on ``<root>/.lock``), used by
:meth:`datamodules.cache.CacheBuilder.locked`: processes preparing one folder at once take turns."""
from __future__ import annotations

import logging
from pathlib import Path

log = logging.getLogger("lit3d.data")


def flock_waiting(f, path: Path) -> None:
    """Exclusive ``flock`` on the open file ``f``; logs once when it has to wait. Without
    ``fcntl`` (Windows) or on a file system that refuses locks: a warning, no lock."""
    try:
        import fcntl
    except ImportError:  # pragma: no cover - not POSIX
        log.warning("%s: no fcntl here: preparing without the inter-process lock", path)
        return
    try:
        fcntl.flock(f.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        return
    except BlockingIOError:
        f.seek(0)
        holder = f.read().strip() or "?"
        log.info("%s: another process (pid %s) is preparing this data; waiting for it", path.parent, holder)
    except OSError as exc:  # e.g. ENOLCK on some network file systems
        log.warning("%s: cannot lock (%s): preparing without the inter-process lock", path, exc)
        return
    fcntl.flock(f.fileno(), fcntl.LOCK_EX)
    log.info("%s: the other preparation is done; going on", path.parent)


def funlock(f) -> None:
    """Forget the holder's pid, then release (closing the file would release it too)."""
    try:
        f.truncate(0)
        f.flush()
        import fcntl

        fcntl.flock(f.fileno(), fcntl.LOCK_UN)
    except (ImportError, OSError):
        pass
