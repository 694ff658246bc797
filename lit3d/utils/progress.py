"""Periodic progress lines for loops that can take longer than a few seconds.

    for mesh in progress(meshes, "canonical forms (cmds, smacof)", log.info):
        ...
    # canonical forms (cmds, smacof): 3/20 (15%) after 12 s, about 68 s left

A line is written when ``every_s`` seconds (default 10) have passed since the previous one, and
after the last item when the whole loop took at least that long; a quick loop stays silent. Plain
lines, not a bar, so log files (Hydra's ``<job>.log``, SLURM output) stay readable.

One long step without items (a library's first build of its cache) gets a heartbeat instead:

    with ticking("building the Anny body model's cache", expected_s=150):
        anny.Anny()
    # building the Anny body model's cache: 40 s, about 1 min 50 s left
"""
from __future__ import annotations

import contextlib
import logging
import os
import sys
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from typing import TypeVar

T = TypeVar("T")
EVERY_S = 10.0


def progress(items: Iterable[T], what: str, emit: Callable[[str], object] | None = None, total: int | None = None,
             every_s: float | None = None) -> Iterator[T]:
    """Yield ``items``, writing :func:`progress_line` through ``emit`` (default: the ``lit3d``
    logger at INFO) at most every ``every_s`` seconds (default :data:`EVERY_S`). ``total``: the item
    count when ``items`` has no ``len``."""
    emit = emit or logging.getLogger("lit3d").info
    every_s = EVERY_S if every_s is None else every_s
    n = total if total is not None else (len(items) if hasattr(items, "__len__") else None)
    start = last = time.monotonic()
    done = 0
    for item in items:
        yield item
        done += 1
        now = time.monotonic()
        if now - last >= every_s or (done == n and now - start >= every_s):
            emit(progress_line(what, done, n, now - start))
            last = now


def progress_line(what: str, done: int, total: int | None, seconds: float) -> str:
    """``"<what>: 3/20 (15%) after 12 s, about 68 s left"`` (``"<what>: 3 done after 12 s"`` without a
    total; ``"<what>: 20/20 done in 80 s"`` at the end)."""
    if total is None:
        return f"{what}: {done} done after {seconds:.0f} s"
    if done >= total:
        return f"{what}: {done}/{total} done in {seconds:.0f} s"
    left = seconds / max(done, 1) * (total - done)
    return f"{what}: {done}/{total} ({100 * done / max(total, 1):.0f}%) after {seconds:.0f} s, about {left:.0f} s left"


def duration(seconds: float) -> str:
    """``"40 s"``, ``"1 min 50 s"``, ``"2 min"`` (whole seconds; minutes from 60 s on)."""
    s = max(0, round(seconds))
    if s < 60:
        return f"{s} s"
    return f"{s // 60} min" + (f" {s % 60} s" if s % 60 else "")


def heartbeat_line(what: str, seconds: float, expected_s: float) -> str:
    """``"<what>: 40 s, about 1 min 50 s left"`` for a step that usually takes ``expected_s``;
    past that, ``"<what>: 3 min 10 s, longer than the usual 2 min 30 s (a busy machine is slower)"``."""
    if seconds < expected_s:
        return f"{what}: {duration(seconds)}, about {duration(expected_s - seconds)} left"
    return f"{what}: {duration(seconds)}, longer than the usual {duration(expected_s)} (a busy machine is slower)"


def say_or_log(line: str) -> None:
    """Where a status line of a shared module goes: the ``lit3d`` logger at INFO where something shows
    those records (the Hydra commands: their console and ``<job>.log``), else stderr as
    ``<command>: <line>`` (the argparse commands, e.g. ``lit3d-reconstruct``, which configure no logging).
    Never stdout: ``lit3d-data`` keeps stdout for its JSON."""
    log = logging.getLogger("lit3d")
    if log.isEnabledFor(logging.INFO) and log.hasHandlers():
        log.info(line)
    else:
        command = os.path.basename(sys.argv[0]) if sys.argv and sys.argv[0] else ""
        print(f"{command if command and not command.startswith('-') else 'lit3d'}: {line}", file=sys.stderr, flush=True)


@contextlib.contextmanager
def ticking(what: str, expected_s: float, emit: Callable[[str], object] | None = None,
            every_s: float | None = None) -> Iterator[None]:
    """Run the block while a daemon thread writes :func:`heartbeat_line` through ``emit`` (default
    :func:`say_or_log`) every ``every_s`` seconds (default :data:`EVERY_S`); a block that ends
    sooner says nothing. The thread stops when the block ends (also on an exception). For one long
    call (native code) that a loop's :func:`progress` cannot see into: the heartbeat runs while the
    call has released the GIL, as torch and file reads do."""
    emit = emit or say_or_log
    every_s = EVERY_S if every_s is None else every_s
    done = threading.Event()
    start = time.monotonic()

    def beat() -> None:
        while not done.wait(every_s):
            emit(heartbeat_line(what, time.monotonic() - start, expected_s))

    thread = threading.Thread(target=beat, name=f"ticking: {what}", daemon=True)
    thread.start()
    try:
        yield
    finally:
        done.set()
        thread.join(timeout=1.0)
