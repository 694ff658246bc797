"""The names of temp files and staging folders, which say who wrote them.

Every temp file of an atomic write (:func:`lit3d.utils.io.atomic_file`) and every staging folder
(:func:`lit3d.utils.io.write_file_set`, the evaluation's ``.evaluation.*``) is named
``.<name>.<pid>-<host>.<random>.tmp``: the writer's pid and a short hash of its host name. A writer
that is killed (SIGKILL, the OOM killer, a power cut) leaves it behind; :func:`writer_gone` tells
such a leftover from the temp of a writer that is still running, on this host (a temp written on
another host is never taken for a leftover: its pid means nothing here). Older names carry the pid
alone (``.<name>.<pid>.<random>.tmp``) and are read as written on this host.
"""
from __future__ import annotations

import hashlib
import os
import re
import socket
from typing import NamedTuple

TMP_SUFFIX = ".tmp"
HOST = hashlib.sha1(socket.gethostname().encode("utf-8", "surrogateescape")).hexdigest()[:6]
_TAGGED = re.compile(r"^\.(?P<name>.+)\.(?P<pid>\d+)(?:-(?P<host>[0-9a-f]{6}))?\.(?P<rand>[^.]+)" + re.escape(TMP_SUFFIX) + "$")


class Writer(NamedTuple):
    name: str  # the file (or set) the temp was for
    pid: int
    host: str | None  # None: an older name, without the host


def tag() -> str:
    """``<pid>-<host>`` of this process, as temp names carry it."""
    return f"{os.getpid()}-{HOST}"


def temp_prefix(name: str) -> str:
    """The start of a temp name for ``name`` written by this process: ``.<name>.<pid>-<host>.``
    (``tempfile`` adds the random part and :data:`TMP_SUFFIX`)."""
    return f".{name}.{tag()}."


def writer(temp_name: str) -> Writer | None:
    """Who wrote the temp file or staging folder of this name; None for a name without a pid."""
    m = _TAGGED.match(temp_name)
    return Writer(m["name"], int(m["pid"]), m["host"]) if m else None


def alive(pid: int) -> bool:
    """A process of this pid runs on this host."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def writer_gone(temp_name: str, *, with_host: bool = False) -> bool:
    """The temp of this name was left by a writer that is gone: written on this host by a process
    that no longer runs. False for this process's own temps, another host's, and names without a
    pid; ``with_host``: only the names that carry the host count (never an older name)."""
    w = writer(temp_name)
    if w is None or (with_host and w.host is None) or w.host not in (None, HOST):
        return False
    return w.pid != os.getpid() and not alive(w.pid)
