"""Completion: training step time / memory at demo scale, and data loading vs the step.

Rows:
- one training step (critic steps + generator step) at demo scale, batch 8, on this machine,
  with peak RSS; samples/s and the projected time of the thesis's 20 epochs x 26,000 samples;
- the packed-bit loader (configured workers) vs raw int8 .npz, against the step's demand.
Paper scale (batch 3, bf16) needs an NVIDIA GPU: it is measured only when CUDA is available.
"""
from __future__ import annotations

import tempfile
from pathlib import Path

import torch
from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra
from omegaconf import open_dict

from benchmarks.common import median_time, peak_rss_mb, row
from lit3d.cli.common import CONF_DIR, build_datamodule, build_task

THESIS_SAMPLES, THESIS_EPOCHS = 26_000, 20


def _cfg(experiment: str, data_dir: str, overrides: list[str] = ()):
    GlobalHydra.instance().clear()
    with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
        cfg = compose("train", overrides=[f"experiment={experiment}", *overrides])
    with open_dict(cfg):
        cfg.paths.output_dir = data_dir
        cfg.paths.data_dir = data_dir
    return cfg


def step_seconds(task, batch: dict, device: str, precision: str | None = None) -> float:
    """Median time of one GAN training step (critic steps + generator step), manual loop."""
    import lightning.pytorch as pl

    trainer = pl.Trainer(accelerator="gpu" if device == "cuda" else "cpu", devices=1, logger=False,
                         enable_checkpointing=False, enable_progress_bar=False, max_steps=1,
                         precision=precision or "32-true", enable_model_summary=False)
    # attach the task to a trainer so toggled_optimizer/manual_backward work
    trainer.strategy.connect(task)
    trainer.strategy._lightning_module = task
    task.trainer = trainer
    task.to(device)
    opts = task.configure_optimizers()
    trainer.strategy.optimizers = opts if isinstance(opts, list) else [opts]
    batch = {k: (v.to(device) if torch.is_tensor(v) else v) for k, v in batch.items()}
    return median_time(lambda: task.training_step(batch, 0), repeats=5, warmup=2)


def run() -> list[dict]:
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        cfg = _cfg("completion_demo", tmp, ["data.sizes={train:64,val:8,test_same:8,test_cross:8,test_unseen:8}"])
        dm = build_datamodule(cfg.data)
        dm.prepare_data()
        dm.setup("fit")
        task = build_task(cfg.task)
        batch = next(iter(dm.train_dataloader()))
        bs = batch["input"].shape[0]
        t_step = step_seconds(task, batch, "cpu")
        sps = bs / t_step
        projected_h = THESIS_EPOCHS * THESIS_SAMPLES / sps / 3600
        rows.append(row(f"completion train step, demo scale 16^3->64^3, batch {bs}, fp32, CPU",
                        "make bench", t_step, None,
                        note=f"{sps:.1f} samples/s; peak RSS {peak_rss_mb():.0f} MB; "
                             f"20 epochs x 26k samples at this scale: {projected_h:.1f} h"))
        from datamodules.voxel_cache import measure_loading

        loading = measure_loading(dm.data_dir, dm.datasets["train"].items, Path(tmp), n=64)
        rows.append(row("completion data loading (packed bits vs raw int8 .npz), demo 64^3, 1 process",
                        "make bench", 1 / loading["packed_bits"], 1 / loading["int8_npz"],
                        unit="s/sample", baseline_name="raw int8 npz",
                        note=f"loader {loading['packed_bits']:.0f} samples/s vs training step "
                             f"{sps:.1f} samples/s: loader keeps up = {loading['packed_bits'] > sps}"))
    if torch.cuda.is_available():  # pragma: no cover - GPU only
        rows += _paper_gpu_rows()
    return rows


def _paper_gpu_rows() -> list[dict]:  # pragma: no cover - GPU only
    rows = []
    cfg = _cfg("completion_paper", tempfile.mkdtemp())
    for precision in ("bf16-mixed", "32-true"):
        task = build_task(cfg.task)
        r, R = 64, 256
        batch = {"input": (torch.rand(3, 1, r, r, r) < 0.05).float(), "target": (torch.rand(3, 1, R, R, R) < 0.1).float(),
                 "label": torch.tensor([0, 1, 2]), "category": ["bench", "chair", "couch"]}
        torch.cuda.reset_peak_memory_stats()
        t = step_seconds(task, batch, "cuda", precision)
        sps = 3 / t
        rows.append(row(f"completion train step, paper scale, batch 3, {precision}", "make bench", t, None,
                        note=f"{sps:.2f} samples/s (target >= 5); peak GPU {torch.cuda.max_memory_allocated() / 2**30:.1f} GiB; "
                             f"20 epochs x 26k: {20 * 26000 / sps / 3600:.1f} h (thesis 4.5 days)"))
        del task
        torch.cuda.empty_cache()
    return rows
