"""A test hook that kills this process at a named point, as SIGKILL, the OOM killer or a power cut
would: the tests of what killed runs leave behind (``tests/e2e/test_leftovers.py``) use it instead of
racing a signal against a write that takes milliseconds.

``LIT3D_KILL_AT=<point>`` kills at the first time the process reaches ``<point>``;
``LIT3D_KILL_AT=<point>@<n>`` at the n-th time. The points: ``write:<file name>`` (an atomic write,
its bytes in the temp file, before the rename), ``evaluation:staged`` (an evaluation's files in its
staging folder, before they are moved), ``file-set:committed`` (a set's journal written, before its
renames). Unset (always, outside the tests) it does nothing.
"""
from __future__ import annotations

import os
import signal

ENV = "LIT3D_KILL_AT"
_reached: dict[str, int] = {}


def kill_point(point: str) -> None:
    """SIGKILL this process when ``LIT3D_KILL_AT`` names ``point`` (and this is its n-th time)."""
    wanted = os.environ.get(ENV)
    if not wanted:
        return
    name, _, nth = wanted.rpartition("@") if "@" in wanted else (wanted, "", "1")
    if name != point:
        return
    _reached[point] = _reached.get(point, 0) + 1
    if _reached[point] == int(nth or 1):
        os.kill(os.getpid(), signal.SIGKILL)
