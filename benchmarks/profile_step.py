"""One-call profile of a completion training step: torch.profiler's top kernels and the GPU's idle time.

For each batch size, a real Lightning ``fit`` of the paper-scale task (``experiment=completion_paper``,
critic on, fp32) on random occupancy batches runs ``warmup`` steps, then one step under
``torch.profiler``; written (markdown) to ``--out``:

- the step's wall time, the device time its kernels keep the GPU busy (their union) and the idle
  time (wall - busy: launch gaps, host work, synchronisations), with the number of kernels;
- the top 25 ops by self device time (``key_averages``; by self CPU time on a machine without CUDA).

    python -m benchmarks.profile_step                        # paper scale, batch 3 and 12 (make bench-gpu)
    python -m benchmarks.profile_step --tiny --out p.md     # demo scale, batch 2, CPU: checks the script
"""
from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import torch
from torch.autograd import DeviceType

from benchmarks.bench_completion import WITH_CRITIC, _cfg, random_batches
from benchmarks.common import num_threads
from lit3d.cli.common import build_task

OUT = Path(__file__).resolve().with_name("gpu_profile.md")
TOP = 25
# --tiny: demo nets shrunk further (32^3 shapes, small latent), critic on; a few seconds on a CPU
TINY = ["task.adversarial=true", "data.target_res=32", "task.nets.latent_dim=64", "task.nets.k=16",
        "task.nets.fixed_latent_dim=64", "task.nets.critic_channels=[8,8,8,8]", "task.nets.enc_channels=[8,16]"]


def kernel_busy_us(intervals: list[tuple[float, float]]) -> float:
    """Length of the union of ``(start, end)`` intervals (us): the time at least one kernel runs."""
    busy, end = 0.0, float("-inf")
    for s, e in sorted(intervals):
        if e <= end:
            continue
        busy += e - max(s, end)
        end = e
    return busy


def profile_step(experiment: str = "completion_paper", batch: int = 3, warmup: int = 2, overrides=()) -> dict:
    """Profile one training step after ``warmup`` steps; ``{"wall_ms", "busy_ms", "idle_ms", "kernels", "table"}``
    (busy/idle/kernels None without CUDA)."""
    import lightning.pytorch as pl
    from torch.profiler import ProfilerActivity, profile
    from torch.utils.data import DataLoader

    cuda = torch.cuda.is_available()
    cfg = _cfg(experiment, tempfile.mkdtemp(), [*WITH_CRITIC, *overrides])
    task = build_task(cfg.task)
    batches = random_batches(warmup + 1, batch, int(cfg.task.nets.in_res), int(cfg.task.nets.out_res))
    activities = [ProfilerActivity.CPU] + ([ProfilerActivity.CUDA] if cuda else [])
    state: dict = {}

    def sync():
        if cuda:
            torch.cuda.synchronize()

    class Profiled(pl.Callback):
        def on_train_batch_start(self, trainer, pl_module, b, batch_idx):
            if batch_idx == warmup:
                sync()
                state["prof"] = profile(activities=activities)
                state["prof"].__enter__()
                state["t0"] = time.perf_counter()

        def on_train_batch_end(self, trainer, pl_module, outputs, b, batch_idx):
            if batch_idx == warmup:
                sync()
                state["wall"] = time.perf_counter() - state["t0"]
                state["prof"].__exit__(None, None, None)

    trainer = pl.Trainer(accelerator="gpu" if cuda else "cpu", devices=1, precision="32-true", max_epochs=1,
                         limit_val_batches=0, num_sanity_val_steps=0, logger=False, enable_checkpointing=False,
                         enable_progress_bar=False, enable_model_summary=False, callbacks=[Profiled()])
    trainer.fit(task, train_dataloaders=DataLoader(batches, batch_size=None, shuffle=False))
    prof = state["prof"]
    sort = "self_device_time_total" if cuda else "self_cpu_time_total"
    out = {"wall_ms": state["wall"] * 1e3, "busy_ms": None, "idle_ms": None, "kernels": None,
           "table": prof.key_averages().table(sort_by=sort, row_limit=TOP)}
    if cuda:
        kernels = [(e.time_range.start, e.time_range.end) for e in prof.events() if e.device_type == DeviceType.CUDA]
        out["kernels"] = len(kernels)
        out["busy_ms"] = kernel_busy_us(kernels) / 1e3
        out["idle_ms"] = out["wall_ms"] - out["busy_ms"]
    return out


def report(results: dict[int, dict], experiment: str) -> str:
    """Markdown: per batch size the step's wall/busy/idle times and the top-ops table."""
    dev = torch.cuda.get_device_name(0) if torch.cuda.is_available() else "CPU (no CUDA: no kernel times)"
    text = f"# Profile of one completion training step\n\n`python -m benchmarks.profile_step`: experiment={experiment}, " \
           f"critic on, fp32, on {dev}, torch {torch.__version__}.\n"
    for b, r in results.items():
        text += f"\n## Batch {b}\n\nStep wall time {r['wall_ms']:.1f} ms"
        if r["busy_ms"] is not None:
            text += (f"; {r['kernels']} kernels keep the GPU busy {r['busy_ms']:.1f} ms; idle between kernels "
                     f"{r['idle_ms']:.1f} ms ({100 * r['idle_ms'] / r['wall_ms']:.0f}% of the step)")
        text += f".\n\nTop {TOP} ops by self {'device' if r['busy_ms'] is not None else 'CPU'} time:\n\n```\n{r['table']}\n```\n"
    return text


def main(argv: list[str] | None = None) -> str:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--tiny", action="store_true", help="demo scale, batch 2, one warm-up step (a check of the script)")
    p.add_argument("--out", type=Path, default=OUT)
    p.add_argument("--batches", default="3,12", help="comma-separated batch sizes (paper scale)")
    a = p.parse_args(argv)
    experiment = "completion_demo" if a.tiny else "completion_paper"
    sizes = [2] if a.tiny else [int(s) for s in a.batches.split(",")]
    results = {}
    with num_threads(1 if a.tiny else None):  # a shared small CPU: per-op thread teams stall (benchmarks.common)
        for b in sizes:
            results[b] = profile_step(experiment, b, warmup=1 if a.tiny else 2, overrides=TINY if a.tiny else [])
            if torch.cuda.is_available():
                torch.cuda.empty_cache()
    text = report(results, experiment)
    a.out.write_text(text)
    print(text)
    return text


if __name__ == "__main__":
    main()
