"""One-call profile of a completion training step: torch.profiler's top kernels and the GPU's idle time.

For each variant (the step switches of conf/task/completion.yaml, :data:`VARIANTS`) and batch size, a real
Lightning ``fit`` of the paper-scale task (``experiment=completion_paper``, critic on, ``--precision``, fp32 by
default) on random occupancy batches runs ``warmup`` steps, then one step under ``torch.profiler``; written
(markdown) to ``--out``:

- a summary: per variant and batch, the step's wall time and samples/s, the device time its kernels keep
  the GPU busy (their union) and the idle time (wall - busy: launch gaps, host work, synchronisations),
  the number of kernels, peak GPU memory, and whether the profiled step ran the gradient penalty (with
  ``task.adversarial.gp_every=N`` one critic update in N does: time both kinds or average over N steps);
- per variant and batch the top 25 ops by self device time (``key_averages``; by self CPU time without CUDA).

    python -m benchmarks.profile_step                        # paper scale, batch 3 and 12 (make bench-gpu)
    python -m benchmarks.profile_step --variants every      # every step switch, one call (a GPU session)
    python -m benchmarks.profile_step --variants default,gp_bf16 --precision bf16-mixed --set task.nets.k=50
    python -m benchmarks.profile_step --tiny --out p.md     # demo scale, batch 2, CPU: checks the script

The compiled variants (``task.compile_step``) compile during the warm-up steps (minutes); the profiled step is
compiled code. ``warmup`` >= 2 so that with ``gp_every`` > 1 both critic updates (with and without the
penalty) have compiled before the profiled step.
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
from lit3d.runtime.build import build_task

OUT = Path(__file__).resolve().with_name("gpu_profile.md")
TOP = 25
# the step switches (conf/task/completion.yaml), one profile each; "every" = all of them in one call
VARIANTS = {
    "default": [],
    "gp_every4": ["task.adversarial.gp_every=4"],
    "critic_concat": ["task.adversarial.critic_concat=true"],
    "gp_bf16": ["task.adversarial.gp_precision=bf16"],
    "compile": ["task.compile_step=true"],
    "all": ["task.adversarial.gp_every=4", "task.adversarial.critic_concat=true", "task.adversarial.gp_precision=bf16",
            "task.compile_step=true"],
}
# --tiny: demo nets shrunk further (32^3 shapes, small latent), critic on; a few seconds on a CPU
TINY = ["task.adversarial.use=true", "data.target_res=32", "task.nets.latent_dim=64", "task.nets.k=16",
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


def profile_step(experiment: str = "completion_paper", batch: int = 3, warmup: int = 2, overrides=(),
                 precision: str = "32-true") -> dict:
    """Profile one training step after ``warmup`` steps; ``{"wall_ms", "busy_ms", "idle_ms", "kernels", "peak_mib",
    "penalty", "table"}`` (busy/idle/kernels/peak None without CUDA; penalty: the profiled step ran the gradient
    penalty)."""
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
                state["penalty"] = pl_module.critic_updates % pl_module.adversarial.gp_every == 0
                if cuda:
                    torch.cuda.reset_peak_memory_stats()
                state["prof"] = profile(activities=activities)
                state["prof"].__enter__()
                state["t0"] = time.perf_counter()

        def on_train_batch_end(self, trainer, pl_module, outputs, b, batch_idx):
            if batch_idx == warmup:
                sync()
                state["wall"] = time.perf_counter() - state["t0"]
                state["prof"].__exit__(None, None, None)

    trainer = pl.Trainer(accelerator="gpu" if cuda else "cpu", devices=1, precision=precision, max_epochs=1,
                         limit_val_batches=0, num_sanity_val_steps=0, logger=False, enable_checkpointing=False,
                         enable_progress_bar=False, enable_model_summary=False, callbacks=[Profiled()])
    trainer.fit(task, train_dataloaders=DataLoader(batches, batch_size=None, shuffle=False))
    prof = state["prof"]
    sort = "self_device_time_total" if cuda else "self_cpu_time_total"
    out = {"wall_ms": state["wall"] * 1e3, "busy_ms": None, "idle_ms": None, "kernels": None, "peak_mib": None,
           "penalty": state["penalty"], "table": prof.key_averages().table(sort_by=sort, row_limit=TOP)}
    if cuda:
        kernels = [(e.time_range.start, e.time_range.end) for e in prof.events() if e.device_type == DeviceType.CUDA]
        out["kernels"] = len(kernels)
        out["busy_ms"] = kernel_busy_us(kernels) / 1e3
        out["idle_ms"] = out["wall_ms"] - out["busy_ms"]
        out["peak_mib"] = torch.cuda.max_memory_allocated() / 2**20
    return out


def _ms(v: float | None) -> str:
    return "–" if v is None else f"{v:.1f}"


def report(results: dict[tuple[str, int], dict], experiment: str, precision: str = "32-true",
           variants: dict[str, list[str]] | None = None) -> str:
    """Markdown: a summary row per (variant, batch size), then each one's wall/busy/idle times and top-ops table."""
    variants = variants or VARIANTS
    dev = torch.cuda.get_device_name(0) if torch.cuda.is_available() else "CPU (no CUDA: no kernel times)"
    text = f"# Profile of one completion training step\n\n`python -m benchmarks.profile_step`: experiment={experiment}, " \
           f"critic on, precision {precision}, on {dev}, torch {torch.__version__}.\n"
    text += ("\n| variant | overrides | batch | wall ms | samples/s | busy ms | idle ms | kernels | peak MiB | penalty |\n"
             "|---|---|---|---|---|---|---|---|---|---|\n")
    for (v, b), r in results.items():
        kernels = "–" if r["kernels"] is None else str(r["kernels"])
        peak = "–" if r["peak_mib"] is None else f"{r['peak_mib']:.0f}"
        text += (f"| {v} | {' '.join(variants.get(v, [])) or '–'} | {b} | {r['wall_ms']:.1f} | {1e3 * b / r['wall_ms']:.2f} "
                 f"| {_ms(r['busy_ms'])} | {_ms(r['idle_ms'])} | {kernels} | {peak} | {'yes' if r['penalty'] else 'no'} |\n")
    for (v, b), r in results.items():
        text += f"\n## {v}, batch {b}\n\nStep wall time {r['wall_ms']:.1f} ms"
        if r["busy_ms"] is not None:
            text += (f"; {r['kernels']} kernels keep the GPU busy {r['busy_ms']:.1f} ms; idle between kernels "
                     f"{r['idle_ms']:.1f} ms ({100 * r['idle_ms'] / r['wall_ms']:.0f}% of the step)")
        text += f".\n\nTop {TOP} ops by self {'device' if r['busy_ms'] is not None else 'CPU'} time:\n\n```\n{r['table']}\n```\n"
    return text


def _variants(spec: str) -> dict[str, list[str]]:
    names = list(VARIANTS) if spec == "every" else [v.strip() for v in spec.split(",") if v.strip()]
    unknown = [v for v in names if v not in VARIANTS]
    if unknown:
        raise SystemExit(f"--variants: unknown {unknown}; choose from {list(VARIANTS)} or 'every'")
    return {v: VARIANTS[v] for v in names}


def main(argv: list[str] | None = None) -> str:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--tiny", action="store_true", help="demo scale, batch 2, one warm-up step (a check of the script)")
    p.add_argument("--out", type=Path, default=OUT)
    p.add_argument("--batches", default="3,12", help="comma-separated batch sizes (paper scale)")
    p.add_argument("--variants", default="default",
                   help=f"comma-separated step switches to profile, of {', '.join(VARIANTS)}; 'every' = all")
    p.add_argument("--precision", default="32-true", help="Lightning precision: 32-true (default) or bf16-mixed")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="an extra config override (repeat)")
    p.add_argument("--warmup", type=int, default=None, help="steps before the profiled one (default 2; --tiny 1)")
    a = p.parse_args(argv)
    experiment = "completion_demo" if a.tiny else "completion_paper"
    sizes = [2] if a.tiny else [int(s) for s in a.batches.split(",")]
    warmup = a.warmup if a.warmup is not None else (1 if a.tiny else 2)
    variants = _variants(a.variants)
    results, failures = {}, {}
    with num_threads(1 if a.tiny else None):  # a shared small CPU: per-op thread teams stall (benchmarks.common)
        for v, overrides in variants.items():
            for b in sizes:
                try:
                    results[v, b] = profile_step(experiment, b, warmup=warmup, precision=a.precision,
                                                 overrides=[*(TINY if a.tiny else []), *overrides, *a.set])
                except Exception as exc:  # one failing variant (OOM, compiler) must not hide the others
                    failures[v, b] = f"{type(exc).__name__}: {str(exc).splitlines()[0][:300] if str(exc) else ''}"
                if torch.cuda.is_available():
                    torch.cuda.empty_cache()
    text = report(results, experiment, a.precision, variants)
    if failures:
        text += "\n## Failed\n\n" + "".join(f"- {v}, batch {b}: {e}\n" for (v, b), e in failures.items())
    a.out.write_text(text)
    print(text)
    return text


if __name__ == "__main__":
    main()
