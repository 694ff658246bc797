"""Periodic progress lines for loops that can take longer than a few seconds.

    for mesh in progress(meshes, "canonical forms (cmds, smacof)", log.info):
        ...
    # canonical forms (cmds, smacof): 3/20 (15%) after 12 s, about 68 s left

A line is written when ``every_s`` seconds (default 10) have passed since the previous one, and
after the last item when the whole loop took at least that long; a quick loop stays silent. Plain
lines, not a bar, so log files (Hydra's ``<job>.log``, SLURM output) stay readable.
"""
from __future__ import annotations

import logging
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
