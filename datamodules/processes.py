"""Preparation jobs in spawned worker processes (rendering a cache's items: independent jobs, each
process building what it needs itself; ``spawn``, so no worker inherits the parent's EGL context or
threads)."""
from __future__ import annotations

import multiprocessing as mp
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ProcessPoolExecutor, as_completed


def spawned_results(fn: Callable, jobs: Iterable[tuple], workers: int) -> Iterator:
    """``fn(*job)`` for every job of ``jobs`` in ``workers`` spawned processes, yielded as they finish
    (not in job order). A job's exception comes out of this iterator; on it, or when the caller stops
    iterating (a stop), the jobs not started are dropped, not waited for."""
    with ProcessPoolExecutor(int(workers), mp_context=mp.get_context("spawn")) as pool:
        try:
            for fut in as_completed([pool.submit(fn, *job) for job in jobs]):
                yield fut.result()
        finally:
            pool.shutdown(cancel_futures=True)
