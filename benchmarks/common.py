"""Timing helpers for the benchmark suite: medians after warm-up, peak memory, machine facts."""
from __future__ import annotations

import platform
import resource
import statistics
import time
from collections.abc import Callable

import torch


def machine() -> str:
    """CPU model and cores, or the GPU name."""
    if torch.cuda.is_available():
        return f"GPU {torch.cuda.get_device_name(0)}"
    model = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    model = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    return f"CPU {model}, {torch.get_num_threads()} threads"


def median_time(fn: Callable[[], object], repeats: int = 5, warmup: int = 1) -> float:
    """Median wall time of ``fn()`` in seconds over ``repeats`` runs after ``warmup`` runs."""
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(repeats):
        if torch.cuda.is_available():
            torch.cuda.synchronize()
        t0 = time.perf_counter()
        fn()
        if torch.cuda.is_available():
            torch.cuda.synchronize()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def peak_rss_mb() -> float:
    """Peak resident memory of this process so far, MB (Linux ru_maxrss is in KB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def row(name: str, command: str, ours: float | None, baseline: float | None, unit: str = "s",
        note: str = "", baseline_name: str = "") -> dict:
    """One BENCHMARKS.md row; ratio = baseline / ours (>1 means we are faster) for times."""
    ratio = (baseline / ours) if (ours and baseline) else None
    return {"name": name, "machine": machine(), "command": command, "ours": ours, "baseline": baseline,
            "unit": unit, "ratio": ratio, "note": note, "baseline_name": baseline_name}
