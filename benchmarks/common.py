"""Timing helpers for the benchmark suite: medians after warm-up, thread control, isolated
memory runs, machine and load facts, and one BENCHMARKS.md row per measurement.

Thread counts matter on a small shared CPU: per-op OpenMP teams stall when another process
holds a core (measured here: a 2-thread completion step took 12-22 s instead of about 1 s
while other jobs loaded the 2-core machine; one thread took 1.5 s either way). Every CPU row
therefore says how many intra-op threads it used, and the machine column carries the 1-min
load average at the time of the row.
"""
from __future__ import annotations

import contextlib
import json
import os
import platform
import resource
import statistics
import subprocess
import sys
import time
from collections.abc import Callable

import torch

from lit3d.utils.step_cost import SavedBytes

GPU_CMD = "make bench-gpu"  # the GPU rows alone (benchmarks.run --gpu), on a CUDA machine


def cpu_model() -> str:
    model = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    model = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    return model


def load_avg() -> float | None:
    """1-minute load average (None where unknown)."""
    try:
        return os.getloadavg()[0]
    except OSError:
        return None


def machine(threads: int | None = None, device: str = "cpu") -> str:
    """``GPU <name>`` or ``CPU <model>, <cores> cores, <threads> thread(s)``, plus the current load."""
    if device == "cuda" and torch.cuda.is_available():
        return f"GPU {torch.cuda.get_device_name(0)}"
    t = torch.get_num_threads() if threads is None else threads
    la = load_avg()
    load = "" if la is None else f", load {la:.1f}"
    return f"CPU {cpu_model()}, {os.cpu_count()} cores, {t} thread{'s' if t != 1 else ''}{load}"


@contextlib.contextmanager
def num_threads(n: int | None):
    """Run the block with ``n`` torch intra-op threads (None: leave as is)."""
    prev = torch.get_num_threads()
    if n is not None:
        torch.set_num_threads(n)
    try:
        yield
    finally:
        torch.set_num_threads(prev)


_DEFAULT_THREADS = torch.get_num_threads()


def default_threads() -> int:
    """The intra-op thread count torch started with in this process (normally the core count)."""
    return _DEFAULT_THREADS


def _sync() -> None:
    if torch.cuda.is_available() and torch.cuda.is_initialized():
        torch.cuda.synchronize()


def timings(fn: Callable[[], object], repeats: int = 5, warmup: int = 1) -> list[float]:
    """Wall times of ``fn()`` in seconds over ``repeats`` runs after ``warmup`` runs."""
    for _ in range(warmup):
        fn()
    out = []
    for _ in range(repeats):
        _sync()
        t0 = time.perf_counter()
        fn()
        _sync()
        out.append(time.perf_counter() - t0)
    return out


def median_time(fn: Callable[[], object], repeats: int = 5, warmup: int = 1) -> float:
    """Median wall time of ``fn()`` in seconds over ``repeats`` runs after ``warmup`` runs."""
    return statistics.median(timings(fn, repeats, warmup))


def peak_rss_mb() -> float:
    """Peak resident memory of this process so far, MB (Linux ru_maxrss is in KB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def current_rss_mb() -> float:
    """Resident memory of this process now, MB."""
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20
    except (OSError, ValueError):
        return peak_rss_mb()


def isolated(target: str, kwargs: dict, timeout: float = 900) -> dict:
    """Run ``module:function(**kwargs) -> dict`` in a fresh Python process and return its result.

    Used where a clean memory high-water mark is needed (``ru_maxrss`` of this process
    already holds the peaks of earlier benchmarks).
    """
    code = ("import json, sys, importlib; m, f = sys.argv[1].split(':'); "
            "r = getattr(importlib.import_module(m), f)(**json.loads(sys.argv[2])); "
            "print('@@RESULT@@' + json.dumps(r))")
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    env = dict(os.environ, PYTHONPATH=root + os.pathsep + os.environ.get("PYTHONPATH", ""))
    proc = subprocess.run([sys.executable, "-c", code, target, json.dumps(kwargs)], capture_output=True, text=True,
                          timeout=timeout, cwd=root, env=env)
    for line in proc.stdout.splitlines():
        if line.startswith("@@RESULT@@"):
            return json.loads(line[len("@@RESULT@@"):])
    raise RuntimeError(f"{target} failed (exit {proc.returncode}): {proc.stderr.strip().splitlines()[-3:]}")


def target_note(label: str, value: float | None, goal: float, higher_is_better: bool, unit: str = "") -> str:
    """``"target >= 5x: met (5.8x)"`` or ``"target < 10 s: missed by 1.3x (13 s)"``."""
    op = ">=" if higher_is_better else "<"
    if value is None:
        return f"target {label} {op} {goal:g}{unit}: not measured"
    ok = value >= goal if higher_is_better else value < goal
    shown = f"{value:.3g}{unit}"
    if ok:
        return f"target {label} {op} {goal:g}{unit}: met ({shown})"
    factor = goal / value if higher_is_better else value / goal
    return f"target {label} {op} {goal:g}{unit}: MISSED by {factor:.2f}x ({shown})"


def row(name: str, command: str, ours: float | None, baseline: float | None, unit: str = "s",
        note: str = "", baseline_name: str = "", threads: int | None = None, device: str = "cpu",
        lower_is_better: bool = True) -> dict:
    """One BENCHMARKS.md row; ratio = baseline / ours for times (>1: we are faster),
    ours / baseline for rates (``lower_is_better=False``)."""
    ratio = None
    if ours and baseline:
        ratio = baseline / ours if lower_is_better else ours / baseline
    return {"name": name, "machine": machine(threads, device), "command": command, "ours": ours, "baseline": baseline,
            "unit": unit, "ratio": ratio, "note": note, "baseline_name": baseline_name}


# peak bytes autograd holds for backward (activations): one meter for the timed rows and the step-cost count
SavedTensorMeter = SavedBytes


def trainer_step_times(task, batches: list, *, accelerator: str = "cpu", precision: str = "32-true",
                       warmup: int = 2, meter: SavedTensorMeter | None = None) -> list[float]:
    """Seconds of each Lightning training step of ``task`` over in-memory ``batches``, warm-up dropped.

    One epoch of a real ``Trainer.fit`` (manual or automatic optimisation, the precision
    plugin's autocast, callbacks of the task); each step is timed from
    ``on_train_batch_start`` to ``on_train_batch_end`` (device synchronised), so data
    loading is not included. No validation, logger or checkpoints. ``meter``: measures the
    saved-for-backward memory of the last step.
    """
    import lightning.pytorch as pl
    from torch.utils.data import DataLoader

    class StepTimer(pl.Callback):
        def __init__(self):
            self.times: list[float] = []
            self._t0 = 0.0

        def on_train_batch_start(self, trainer, pl_module, batch, batch_idx):
            if meter is not None and batch_idx == len(batches) - 1:
                meter.__enter__()
            _sync()
            self._t0 = time.perf_counter()

        def on_train_batch_end(self, trainer, pl_module, outputs, batch, batch_idx):
            _sync()
            self.times.append(time.perf_counter() - self._t0)
            if meter is not None and batch_idx == len(batches) - 1:
                meter.__exit__(None, None, None)

    timer = StepTimer()
    trainer = pl.Trainer(accelerator=accelerator, devices=1, precision=precision, max_epochs=1,
                         limit_val_batches=0, num_sanity_val_steps=0, logger=False, enable_checkpointing=False,
                         enable_progress_bar=False, enable_model_summary=False, callbacks=[timer])
    trainer.fit(task, train_dataloaders=DataLoader(batches, batch_size=None, shuffle=False))
    return timer.times[warmup:]
