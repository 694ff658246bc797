"""The worker threads that measure whole views (:func:`view_workers`, :func:`view_worker_count`)."""
from __future__ import annotations

from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from typing import Any

import torch



class _Now:
    """The result of a call made at once, with a :class:`concurrent.futures.Future`'s ``result()``."""

    def __init__(self, fn, *args, **kwargs):
        self.value = fn(*args, **kwargs)

    def result(self):
        return self.value


def view_worker_count(workers: int, device=None) -> int:
    """How many threads :func:`view_workers` runs calls on (1: every call at once in the caller): ``workers``, or
    ``torch.get_num_threads()`` for 0, on CPU; 1 on other devices. Read it before entering :func:`view_workers`
    (which sets the caller's intra-op threads to 1)."""
    on_cpu = device is None or torch.device(device).type == "cpu"
    return (workers if workers > 0 else torch.get_num_threads()) if on_cpu else 1


@contextmanager
def view_workers(workers: int, device=None) -> Iterator[Callable[..., Any]]:
    """``submit(fn, *args)`` -> an object with ``result()``, for measuring whole views in parallel.

    On CPU (``device`` None or a CPU device): ``workers`` threads (0 = ``torch.get_num_threads()``
    on entry), each with one intra-op thread, and one intra-op thread in the caller too (also with
    one worker). Per-op OpenMP teams on small crops stall badly on a busy machine: measured on a
    loaded 2-core CPU, workers=1 with 2 intra-op threads took 18-88 s for the 256^2 table that
    takes about 5 s with one thread. Other devices, or one worker: every call runs at once in the
    caller. On exit the pool is drained and the caller's thread count restored.
    """
    on_cpu = device is None or torch.device(device).type == "cpu"
    n = view_worker_count(workers, device)
    prev = torch.get_num_threads()
    pool = None
    if on_cpu:
        torch.set_num_threads(1)
    try:
        if n > 1:
            pool = ThreadPoolExecutor(n, initializer=torch.set_num_threads, initargs=(1,))
        yield pool.submit if pool is not None else _Now
    finally:
        if pool is not None:
            pool.shutdown(wait=True)
        torch.set_num_threads(prev)
