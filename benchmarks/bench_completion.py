"""Completion: training step time and memory, data loading against the step, data generation.

Rows:
- one training step (``critic_steps`` critic updates + one generator update, as in the
  thesis) at demo scale (16^3 -> 64^3, batch 8, fp32) on this CPU: median step time, samples/s,
  the projected time of the thesis's 20 epochs x 26,000 samples at this scale, and the
  activation memory per sample (slope between batch 4 and batch 8 of the peak bytes autograd
  holds for backward, :class:`benchmarks.common.SavedTensorMeter`; each batch size in a fresh process);
- the packed-bit cache through the configured ``DataLoader`` (``data.num_workers``,
  ``data.batch_size``) against the same pairs as raw int8 ``.npz``, at demo scale (against the
  step's samples/s: does the loader keep up?) and at paper scale (256^3, batch 3);
- synthetic data generation (``CompletionDataModule.prepare_data``: shape, depth render,
  back-projection, solid, packed write) at 64^3 and 256^3;
- paper scale (64^3 -> 256^3, batch 3) on an NVIDIA GPU: fp32 (the baseline) against
  bf16-mixed, channels_last_3d and ``torch.compile`` of the generator; samples/s, peak GPU
  memory per sample and the projected 20 x 26,000-sample training time. Without CUDA these
  rows are listed without figures.

The demo experiment trains the generator alone for 6 warm-up epochs; the benchmark sets
``task.adversarial.start_epoch=0`` so that every timed step includes the critic update and
its gradient penalty.
"""
from __future__ import annotations

import statistics
import tempfile
import time
from pathlib import Path

import torch
from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra
from omegaconf import open_dict

from benchmarks.common import (GPU_CMD, SavedTensorMeter, current_rss_mb, default_threads, isolated, num_threads,
                               peak_rss_mb, row, target_note, trainer_step_times)
from lit3d.runtime.build import build_datamodule, build_task
from lit3d.runtime.compose import CONF_DIR
from lit3d.utils.shapenet_categories import SEEN_CATEGORIES

THESIS_SAMPLES, THESIS_EPOCHS = 26_000, 20
GPU_TARGET_SPS = 5.0  # samples/s at paper scale on one GPU (the target)
WITH_CRITIC = ["task.adversarial.start_epoch=0"]
CMD = "make bench"


def _cfg(experiment: str, data_dir: str, overrides=()):
    GlobalHydra.instance().clear()
    with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
        cfg = compose("train", overrides=[f"experiment={experiment}", *overrides])
    with open_dict(cfg):
        cfg.paths.output_dir = data_dir
        cfg.paths.data_dir = data_dir
    return cfg


def random_batches(n: int, batch: int, in_res: int, out_res: int, seed: int = 0, device: str = "cpu") -> list[dict]:
    """``n`` batches of random occupancy (10 %) with the partial input max-pooled from the target."""
    g = torch.Generator().manual_seed(seed)
    cats = SEEN_CATEGORIES
    out = []
    for _ in range(n):
        y = (torch.rand(batch, 1, out_res, out_res, out_res, generator=g) < 0.1).float()
        x = torch.nn.functional.adaptive_max_pool3d(y, in_res)
        out.append({"input": x.to(device), "target": y.to(device), "label": torch.arange(batch) % len(cats),
                    "category": [cats[i % len(cats)] for i in range(batch)]})
    return out


def step_worker(experiment: str = "completion_demo", batch: int = 8, threads: int = 1, steps: int = 7,
                warmup: int = 2, overrides: list | None = None) -> dict:
    """Step times and memory of one configuration (run in a fresh process by :func:`isolated`)."""
    torch.set_num_threads(threads)
    with tempfile.TemporaryDirectory() as tmp:
        cfg = _cfg(experiment, tmp, [*WITH_CRITIC, *(overrides or [])])
        task = build_task(cfg.task)
        nets = cfg.task.nets
        in_res, out_res = int(nets.in_res), int(nets.out_res)
        batches = random_batches(steps, batch, in_res, out_res)
        idle = current_rss_mb()
        meter = SavedTensorMeter()
        times = trainer_step_times(task, batches, warmup=warmup, meter=meter)
        state_mb = sum(p.numel() * p.element_size() for p in task.parameters()) * 4 / 2**20  # + grads + 2 Adam
    return {"times": times, "idle_rss_mb": idle, "peak_rss_mb": peak_rss_mb(),
    "critic_steps": int(cfg.task.adversarial.critic_steps),
            "in_res": in_res, "out_res": out_res, "saved_mb": meter.peak / 2**20, "state_mb": state_mb}


def _step_rows() -> tuple[list[dict], float]:
    one = {b: isolated("benchmarks.bench_completion:step_worker", {"batch": b, "threads": 1}) for b in (4, 8)}
    nthreads = default_threads()
    multi = isolated("benchmarks.bench_completion:step_worker", {"batch": 8, "threads": nthreads}) if nthreads > 1 else None
    r8 = one[8]
    t = statistics.median(r8["times"])
    sps = 8 / t
    projected_h = THESIS_EPOCHS * THESIS_SAMPLES / sps / 3600
    work = {b: one[b]["peak_rss_mb"] - one[b]["idle_rss_mb"] for b in one}
    saved = {b: one[b]["saved_mb"] for b in one}
    per_sample = (saved[8] - saved[4]) / 4
    note = (f"{r8['critic_steps']} critic update(s) with gradient penalty + 1 generator update per step; "
            f"{sps:.2f} samples/s; 20 epochs x 26k samples at this scale: {projected_h:.1f} h")
    if multi:
        tm = statistics.median(multi["times"])
        note += f"; with {nthreads} threads: {tm:.2f} s/step ({8 / tm:.2f} samples/s)"
    rows = [row(f"completion train step, demo {r8['in_res']}^3->{r8['out_res']}^3, batch 8, fp32, CPU", CMD, t, None,
                unit="s/step", threads=1, note=note + "; random occupancy batches; no baseline (time per step)"),
            row("completion train step peak memory per sample, demo, batch 8, fp32, CPU", CMD, per_sample, None,
                unit="MB/sample", threads=1,
                note=f"activation memory: slope between batch 4 ({saved[4]:.0f} MB) and batch 8 ({saved[8]:.0f} MB) of "
                     f"the peak bytes autograd holds for backward during a step (critic + generator updates); fixed: "
                     f"weights + grads + Adam states {r8['state_mb']:.0f} MB; whole-process peak RSS above idle "
                     f"{work[4]:.0f} MB (batch 4) / {work[8]:.0f} MB (batch 8), each in a fresh process, too coarse "
                     f"for a per-sample figure (allocator caching)")]
    return rows, sps


def _prepare(cfg) -> tuple[object, float, int]:
    dm = build_datamodule(cfg.data)
    t0 = time.perf_counter()
    dm.prepare_data()
    dt = time.perf_counter() - t0
    dm.setup("fit")
    n = sum(int(v) for v in cfg.data.sizes.values())
    return dm, dt, n


def _loading_row(dm, cfg, tmp: Path, scale: str, demand_sps: float | None, demand_name: str) -> dict:
    from datamodules.completion.voxel_cache import measure_loading

    bs, workers = int(cfg.data.batch_size), int(cfg.data.num_workers)
    items = dm.datasets["train"].items
    with num_threads(1):
        r = measure_loading(dm.data_dir, items, tmp / f"int8_{scale}", n=len(items), batch_size=bs, num_workers=workers)
    ours, base = r["packed_bits"], r["int8_npz"]
    note = (f"DataLoader with the configured num_workers={workers}, batch {bs}; {len(items)} items, page cache warm; "
            f"zlib-compressed int8 npz: {r['int8_npz_compressed']:.1f} samples/s; on disk per item: packed "
            f"{r['bytes_per_item/packed_bits'] / 1024:.0f} KB, int8 {r['bytes_per_item/int8_npz'] / 1024:.0f} KB")
    if demand_sps:
        keeps = ours >= demand_sps
        note += (f"; loader {ours:.1f} samples/s vs {demand_name} {demand_sps:.2f} samples/s: loader keeps up = "
                 f"{'yes' if keeps else 'NO'} ({ours / demand_sps:.1f}x the demand)")
    res = int(cfg.data.target_res)
    return row(f"completion data loading, {scale} {res // int(cfg.data.input_factor)}^3 + {res}^3, packed bits vs raw "
               f"int8 npz", CMD, ours, base, unit="samples/s", baseline_name="raw int8 npz", threads=1, note=note,
               lower_is_better=False)


def _gen_row(scale: str, res: int, n: int, seconds: float) -> dict:
    return row(f"synthetic completion data generation, {scale} {res // 4}^3 + {res}^3", CMD, n / seconds, None,
               unit="samples/s", threads=1,
               note=f"CompletionDataModule.prepare_data of {n} items (procedural shape, depth render (EGL), "
                    f"back-projection, solid occupancy, packed-bit write), 1 process")


def run() -> list[dict]:
    rows, train_sps = _step_rows()
    with tempfile.TemporaryDirectory() as tmp_s, num_threads(1):
        tmp = Path(tmp_s)
        demo = _cfg("completion_demo", str(tmp / "demo"),
                    ["data.sizes={train:64,val:8,test_same:8,test_cross:8,test_unseen:8}", "data.prepare.progress=false"])
        dm, dt, n = _prepare(demo)
        rows.append(_gen_row("demo", int(demo.data.target_res), n, dt))
        rows.append(_loading_row(dm, demo, tmp, "demo", train_sps, "demo training step (1 thread)"))
        paper = _cfg("completion_paper", str(tmp / "paper"),
                     ["data.sizes={train:12,val:0,test_same:0,test_cross:0,test_unseen:0}", "data.prepare.progress=false"])
        dm, dt, n = _prepare(paper)
        rows.append(_gen_row("paper", int(paper.data.target_res), n, dt))
        rows.append(_loading_row(dm, paper, tmp, "paper", GPU_TARGET_SPS, "the paper-scale GPU step target"))
    return rows + gpu_rows()


def gpu_rows() -> list[dict]:
    """The paper-scale GPU step rows (``python -m benchmarks.run --gpu``): the thesis's batch of 3 in every
    variant, then batch 12 in fp32 and bf16 + channels_last_3d; a placeholder row without CUDA."""
    if not torch.cuda.is_available():
        return [_gpu_placeholder()]
    return paper_gpu_rows() + paper_gpu_rows(batch=12, steps=4, warmup=2, variants=(GPU_VARIANTS[0], GPU_VARIANTS[2]))


# ---------------------------------------------------------------------------------- GPU
# (name, Lightning precision, task.channels_last, torch.compile of the generator)
GPU_VARIANTS = (
    ("fp32", "32-true", False, False),
    ("bf16-mixed", "bf16-mixed", False, False),
    ("bf16-mixed + channels_last_3d", "bf16-mixed", True, False),
    ("bf16-mixed + torch.compile", "bf16-mixed", False, True),
    ("bf16-mixed + channels_last_3d + torch.compile", "bf16-mixed", True, True),
)


def _gpu_placeholder() -> dict:
    return row("completion train step, paper 64^3->256^3, batch 3, GPU: fp32 vs bf16-mixed, channels_last_3d on/off, "
               "torch.compile on/off", GPU_CMD, None, None, unit="s/step",
               note="not measured: no CUDA device on this machine. On a GPU `make bench` runs "
                    "`paper_gpu_rows()`: samples/s, peak GPU memory per sample and the projected time of 20 epochs x "
                    f"26,000 samples per variant, fp32 as the baseline; target >= {GPU_TARGET_SPS:g} samples/s")


def paper_gpu_rows(experiment: str = "completion_paper", device: str = "cuda", batch: int = 3, steps: int = 8,
                   warmup: int = 3, variants=GPU_VARIANTS, overrides=()) -> list[dict]:
    """One row per variant of the paper-scale training step on ``device`` (fp32 first: the baseline).

    ``torch.compile`` is applied to the generator only: the critic's gradient penalty needs a
    double backward, which compiled graphs do not support. ``device="cpu"`` (with the demo
    experiment) exercises the same code in the tests.
    """
    rows: list[dict] = []
    base_t = None
    cuda = device == "cuda"
    for name, precision, channels_last, compiled in variants:
        try:
            cfg = _cfg(experiment, tempfile.mkdtemp(), [*WITH_CRITIC, f"task.channels_last={channels_last}",
                                                         *overrides])
            task = build_task(cfg.task)
            if compiled:
                task.generator.compile()
            nets = cfg.task.nets
            batches = random_batches(steps, batch, int(nets.in_res), int(nets.out_res))
            if cuda:
                torch.cuda.empty_cache()
                torch.cuda.reset_peak_memory_stats()
            times = trainer_step_times(task, batches, accelerator="gpu" if cuda else "cpu", precision=precision,
                                       warmup=warmup)
            t = statistics.median(times)
            sps = batch / t
            mem = torch.cuda.max_memory_allocated() / 2**20 / batch if cuda else None
            if base_t is None:
                base_t = t
            note = (f"{sps:.2f} samples/s; 20 epochs x 26k samples: {THESIS_EPOCHS * THESIS_SAMPLES / sps / 3600:.1f} h "
                    f"(thesis: about 4.5 days); "
                    + (f"peak GPU memory {mem:.0f} MiB/sample; " if mem is not None else "")
                    + target_note("samples/s", sps, GPU_TARGET_SPS, True)
                    + ("" if name == variants[0][0] else f"; baseline = {variants[0][0]} of this run"))
            rows.append(row(f"completion train step, paper 64^3->256^3, batch {batch}, {name}", GPU_CMD, t,
                            None if name == variants[0][0] else base_t, unit="s/step",
                            baseline_name="" if name == variants[0][0] else variants[0][0], note=note,
                            device=device))
            print(f"[bench-gpu] {rows[-1]['name']}: {note}", flush=True)
            del task, batches
        except Exception as exc:  # one failing variant (OOM, compiler) must not hide the others
            rows.append(row(f"completion train step, paper, batch {batch}, {name}", GPU_CMD, None, None, unit="s/step",
                            note=f"failed: {type(exc).__name__}: {str(exc).splitlines()[0][:200]}", device=device))
        if cuda:
            torch.cuda.empty_cache()
    return rows
