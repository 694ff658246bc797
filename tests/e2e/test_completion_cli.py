"""End-to-end wiring of the completion task through lit3d-train / lit3d-eval / lit3d-summary / lit3d-data."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from lit3d.runtime.errors import UserError
from lit3d.cli.evaluate import evaluate
from lit3d.cli.train import train
from lit3d.utils.tables import fmt
from tests.helpers.paths import REPO

TINY = [
    "experiment=completion_demo",
    "data.sizes={train:16,val:8,test_same:8,test_cross:8,test_unseen:8}",
    "data.batch_size=4",
    "callbacks.progress_bar=null",
]


@pytest.fixture(scope="module")
def data_dir(tmp_path_factory):
    """One tiny synthetic dataset shared by the tests of this module."""
    return tmp_path_factory.mktemp("completion_data")


def bin_path(name: str) -> str:
    return str(Path(sys.executable).parent / name)


@pytest.mark.slow  # 20 s; the wheel test trains debug=fdr and test_train_then_eval a whole run in the default suite
def test_fast_dev_run(compose_cfg, data_dir):
    cfg = compose_cfg([*TINY, "debug=fdr"], data_dir=data_dir)
    train(cfg)
    metrics = json.loads((Path(cfg.paths.output_dir) / "metrics.json").read_text())
    assert "test/same/iou" in metrics and "test/unseen/iou_input" in metrics
    assert 0.0 <= metrics["test/same/iou"] <= 1.0
    # pooled IoU, the extrusion baseline and the paired comparison with intervals, in results.md too
    assert {"test/same/iou_pooled", "test/same/iou_extrusion", "test/same/paired/margin_input_lo"} <= set(metrics)
    results = (Path(cfg.paths.output_dir) / "results.md").read_text()
    assert "Paired comparison, same view" in results and "silhouette extrusion (ours)" in results
    # surface metrics (evaluation.surface) for the model and every baseline, beside IoU in results.md
    assert {f"test/same/{k}{s}" for k in ("chamfer_l1", "fscore_1pct", "fscore_2pct", "normal_consistency")
            for s in ("", "_input", "_extrusion", "_prior")} <= set(metrics)
    assert "## Surface metrics, same view" in results


def test_critic_and_generator_steps_per_batch(compose_cfg, data_dir):
    # not fast_dev_run: it sets max_steps, and a GAN batch makes critic_steps + 1 optimiser steps
    cfg = compose_cfg([*TINY, "debug=limit", "trainer.max_epochs=1", "trainer.limit_train_batches=3",
                       "trainer.limit_val_batches=0", "task.adversarial.critic_steps=2", "task.adversarial.start_epoch=0",
                       "task.adversarial.use=true", "logger=none"], data_dir=data_dir)
    from lit3d.runtime.build import build_datamodule, build_task
    from hydra.utils import instantiate

    task, dm = build_task(cfg.task), build_datamodule(cfg.data)
    trainer = instantiate(cfg.trainer, logger=False, enable_checkpointing=False)
    trainer.fit(task, datamodule=dm)
    opt_g, opt_d = task.optimizers()
    g_steps = {int(s["step"]) for s in opt_g.optimizer.state.values()}
    d_steps = {int(s["step"]) for s in opt_d.optimizer.state.values()}
    assert g_steps == {3} and d_steps == {6}
    assert task.generator_steps == 3


def test_train_then_eval_writes_tables_and_figures(compose_cfg, data_dir, tmp_path):
    # 2000 surface points (the demo samples 10000): the wiring is what is tested here
    cfg = compose_cfg([*TINY, "debug=limit", "logger=csv", "evaluation.surface.points=2000"], data_dir=data_dir)
    value = train(cfg)
    run = Path(cfg.paths.output_dir)
    assert (run / "checkpoints" / "last.ckpt").is_file()
    best = sorted((run / "checkpoints").glob("best-*.ckpt"))
    assert len(best) == 1
    assert (run / "config.yaml").is_file()
    metrics = json.loads((run / "metrics.json").read_text())
    assert metrics["monitor"] == "val/iou" and value == pytest.approx(metrics["monitored_value"])
    # checkpoints load with torch's safe loader, and carry the evaluation settings the test used
    saved = torch.load(best[0], map_location="cpu", weights_only=True)
    assert saved["lit3d"]["evaluation"]["surface"]["points"] == 2000 and "test/same/chamfer_l1" in metrics
    # the tested (best) weights' validation IoU, as lit3d-eval measures it, in metrics.json and results.md
    assert metrics["val/iou"] == pytest.approx(metrics["monitored_value"])
    assert f"(validation IoU {fmt(metrics['val/iou'])})." in (run / "results.md").read_text()

    ecfg = compose_cfg([f"ckpt_path={best[0]}", "task=completion"], config_name="eval", data_dir=data_dir)
    emetrics = evaluate(ecfg)
    out = Path(ecfg.paths.output_dir)
    assert (out / "metrics.json").is_file() and "test/same/iou" in emetrics
    assert "test/same/chamfer_l1" in emetrics  # evaluation.surface: the checkpoint's, set up before the test
    assert emetrics["val/iou"] == pytest.approx(metrics["val/iou"], abs=1e-6)  # the same weights, the same number
    text = (out / "results.md").read_text()
    assert "Tables 3.1 / 3.2" in text and "(thesis 3.2)" in text and "lit3d, multi-category (ours)" in text
    assert list(out.glob("completion_*.png"))

    bad = compose_cfg([f"ckpt_path={best[0]}", "task=canonical"], config_name="eval", data_dir=data_dir)
    with pytest.raises(UserError, match="checkpoint is for task 'completion'"):
        evaluate(bad)


def test_resume_continues_epoch_optimizer_and_wandb_run(compose_cfg, data_dir):
    # test_after_fit=false: what is checked here is the fit state, not the test (test_train_then_eval covers it)
    first = compose_cfg([*TINY, "debug=limit", "trainer.max_epochs=1", "logger=wandb", "test_after_fit=false"],
                        data_dir=data_dir)
    train(first)
    run = Path(first.paths.output_dir)
    ck1 = torch.load(run / "checkpoints" / "last.ckpt", map_location="cpu", weights_only=True)
    assert ck1["epoch"] == 0
    second = compose_cfg([*TINY, "debug=limit", "trainer.max_epochs=2", "logger=wandb", "ckpt_path=last",
                          "test_after_fit=false"],
                         data_dir=data_dir)
    train(second)
    ck2 = torch.load(run / "checkpoints" / "last.ckpt", map_location="cpu", weights_only=True)
    # two epochs done in all, the second one after the resume
    assert ck2["loops"]["fit_loop"]["epoch_progress"]["current"]["completed"] == 2
    assert ck2["global_step"] == 2 * ck1["global_step"]
    # Adam's step counter continued from the first run: optimizer state was restored
    s1 = {int(s["step"]) for s in ck1["optimizer_states"][0]["state"].values()}
    s2 = {int(s["step"]) for s in ck2["optimizer_states"][0]["state"].values()}
    assert s2 == {2 * next(iter(s1))}
    assert ck2["generator_steps"] == 2 * ck1["generator_steps"]
    assert ck1["lit3d"]["wandb_id"] == ck2["lit3d"]["wandb_id"]
    runs = list((run / "wandb").glob(f"offline-run-*-{ck1['lit3d']['wandb_id']}"))
    assert runs, "offline W&B run of the same id"


def test_resume_without_checkpoint_is_a_clear_error(compose_cfg, data_dir):
    cfg = compose_cfg([*TINY, "ckpt_path=last"], data_dir=data_dir)
    with pytest.raises(UserError, match="no last checkpoint"):
        train(cfg)


def _run(args: list[str], cwd: Path, timeout: int = 600, full_error: bool = True) -> subprocess.CompletedProcess:
    env = {**os.environ, "WANDB_MODE": "offline", "WANDB_SILENT": "true"}
    env.pop("HYDRA_FULL_ERROR", None)
    if full_error:
        env["HYDRA_FULL_ERROR"] = "1"
    return subprocess.run(args, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)


def test_summary_paper_scale_shapes():
    res = _run([bin_path("lit3d-summary"), "experiment=completion_paper", "hydra.run.dir=/tmp/lit3d_summary_test"], REPO)
    assert res.returncode == 0, res.stderr
    assert "1x1x64x64x64" in res.stdout and "1x1x256x256x256" in res.stdout
    assert "generator stage 3" in res.stdout and "critic" in res.stdout and "classifier" in res.stdout


@pytest.mark.slow  # default suite under 10 min; runs in make test-all
def test_multirun_sweep_collects_table(data_dir, tmp_path):
    sweep_dir = tmp_path / "sweep"
    res = _run([bin_path("lit3d-train"), "-m", *TINY, "+sweep=completion_classifier", "debug=fdr",
                f"paths.data_dir={data_dir}", f"paths.log_dir={tmp_path}/logs", f"hydra.sweep.dir={sweep_dir}"], REPO)
    assert res.returncode == 0, res.stderr[-3000:]
    jobs = sorted(p for p in sweep_dir.iterdir() if (p / "metrics.json").is_file())
    assert len(jobs) == 2
    table = (sweep_dir / "sweep_results.md").read_text()
    assert "task.nets.classifier=true" in table and "task.nets.classifier=false" in table


@pytest.mark.slow  # 21 s; DDP stays in the default suite through tests/e2e/test_ddp_equivalence.py
def test_ddp_cpu_fast_dev_run(data_dir, tmp_path):
    out = tmp_path / "ddp"
    res = _run([bin_path("lit3d-train"), *TINY, "trainer=ddp_cpu", "trainer.fast_dev_run=2",
                f"paths.data_dir={data_dir}", f"hydra.run.dir={out}"], REPO)
    assert res.returncode == 0, res.stderr[-3000:]
    metrics = json.loads((out / "metrics.json").read_text())
    assert "test/same/iou" in metrics


def test_data_cli_prints_manifest_and_writes_png(data_dir, tmp_path):
    out = tmp_path / "data_run"
    res = _run([bin_path("lit3d-data"), *TINY, f"paths.data_dir={data_dir}", f"hydra.run.dir={out}", "--show", "4"], REPO)
    assert res.returncode == 0, res.stderr[-3000:]
    info = json.loads(res.stdout)  # stdout is the JSON alone (log and "wrote" lines on stderr): `> file.json` works
    assert "manifest_hash" in info
    assert json.loads((out / "data_summary.json").read_text()) == info  # the same JSON in the run dir
    assert (out / "completion_samples.png").is_file() and "completion_samples.png" in res.stderr


def test_missing_data_root_is_one_line(tmp_path):
    res = _run([bin_path("lit3d-train"), "experiment=completion_demo", "data=recgan", f"hydra.run.dir={tmp_path}/r"], REPO,
               full_error=False)
    assert res.returncode == 2
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert lines == ["error: missing value for data.root: set data.root=... on the command line"]
