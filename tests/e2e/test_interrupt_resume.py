"""Training and data preparation survive being stopped, and resume exactly.

- ``lit3d-train`` stopped by SIGTERM (canonical task, default suite) or SIGKILL (completion GAN,
  ``slow``) after the first epoch: ``ckpt_path=last`` resumes at the saved epoch and step, with
  the optimizer, the RNG state (``ResumeState``) and the loss-phase state, and ends at the
  full run's step count.
- ``lit3d-data`` killed (SIGKILL) half way through the synthetic completion set: finished
  items are kept (not redone, same mtimes), no half-written item, and the resumed cache has
  the manifest hash of an uninterrupted preparation; the canonical cache hash is the same in
  another process (same seed) and differs for another seed.
- NaN/Inf losses: ``task.on_nonfinite=raise`` stops with exit 1 and one line naming the step
  and the term; ``skip`` skips and counts without touching the weights; an unknown mode is
  refused by both tasks.
- The RNG state ``ResumeState`` stores survives a ``weights_only`` load and restores the streams.

Subprocesses run with one torch thread (``OMP_NUM_THREADS=1``): on the 2 shared cores of the
test machine that is several times faster than two threads for these tiny nets.
"""
from __future__ import annotations

import csv
import json
import signal
import subprocess
import time
from pathlib import Path

import pytest
import torch

from lit3d.cli.common import run_cli
from lit3d.runtime.build import build_datamodule
from lit3d.cli.train import train
from tests.helpers.runs import BIN, CANONICAL, CANONICAL_STEPS_PER_EPOCH, REPO, child_env, load_checkpoint, start_script


PHASES = [{"start": 0, "alpha": 10.0, "beta": 1000.0}, {"start": 1, "alpha": 1000.0, "beta": 1000.0},
          {"start": 2, "alpha": 1000.0, "beta": 100.0}]


def _phases_override(phases: list[dict]) -> str:
    return "task.phases.weights=[" + ",".join("{" + ",".join(f"{k}:{v}" for k, v in p.items()) + "}" for p in phases) + "]"


# completion demo nets (64^3) on 16 synthetic training items: 4 batches of 4; the critic from step 0,
# so every batch makes 2 optimizer steps (critic + generator)
COMPLETION = [
    "experiment=completion_demo", "data.sizes={train:16,val:4,test_same:0,test_cross:0,test_unseen:0}",
    "data.batch_size=4", "data.prepare.progress=false", "task.adversarial.start_epoch=0", "task.adversarial.use=true",
    "test_after_fit=false",
    "callbacks.progress_bar=null", "+trainer.limit_val_batches=0",
]
COMPLETION_BATCHES_PER_EPOCH = 4








def _wait_for_checkpoint(proc: subprocess.Popen, path: Path, ready, log: Path, timeout: float = 240) -> dict:
    """Poll ``path`` until ``ready(ckpt)``; every read must succeed (writes are atomic)."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        if proc.poll() is not None:
            pytest.fail(f"training ended (rc {proc.returncode}) before the checkpoint was ready:\n"
                        f"{log.with_suffix('.err').read_text()[-3000:]}")
        if path.is_file():
            ckpt = load_checkpoint(path)  # a half-written file would raise here
            if ready(ckpt):
                return ckpt
        time.sleep(0.2)
    proc.kill()
    pytest.fail(f"no checkpoint ready after {timeout} s")


def _adam_steps(ckpt: dict, i: int = 0) -> set[int]:
    return {int(s["step"]) for s in ckpt["optimizer_states"][i]["state"].values()}


def _csv_rows(run: Path, version: int) -> list[dict]:
    with open(run / "csv" / f"version_{version}" / "metrics.csv") as f:
        return list(csv.DictReader(f))


@pytest.fixture(scope="module")
def canonical_data(tmp_path_factory) -> Path:
    """``paths.data_dir`` shared by the canonical runs of this module (rendered once)."""
    return tmp_path_factory.mktemp("canonical_data")


# ----------------------------------------------------------------------------- SIGTERM: canonical
def test_sigterm_saves_last_and_resume_continues_canonical(tmp_path, canonical_data):
    run = tmp_path / "run"
    per_epoch = 8  # batches of 2: a SIGTERM mostly lands mid-epoch (the case Lightning resumes specially)
    # task.phases.alpha/beta are the constant weights (used without phases): set apart from every phase's,
    # so a resumed step that missed its phase's weights shows in the logged losses
    # the redraw head: its loss is exactly alpha * depth + beta * mask (the warp head adds flow terms)
    common = [*CANONICAL, "task.net.head.kind=redraw", "data.batch_size=2", "task.phases.alpha=1.0", "task.phases.beta=1.0",
              "task.phases.unit=epochs",
              "logger=csv", "trainer.log_every_n_steps=1", "callbacks.resume_state.every_n_train_batches=1",
              f"paths.data_dir={canonical_data}", f"hydra.run.dir={run}"]
    last = run / "checkpoints" / "last.ckpt"
    proc = start_script(["lit3d-train", *common, _phases_override(PHASES), "trainer.max_epochs=500"], tmp_path / "first")
    _wait_for_checkpoint(proc, last, lambda c: c["epoch"] >= 1 and c["global_step"] > per_epoch, tmp_path / "first")
    proc.send_signal(signal.SIGTERM)
    assert proc.wait(timeout=120) == 143
    err = (tmp_path / "first.err").read_text()
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert "Traceback" not in err
    assert [ln for ln in lines if ln.startswith("error:")] == [lines[-1]], err[-2000:]
    assert lines[-1].startswith(f"error: {run}: stopped by SIGTERM at epoch ")
    assert f"hydra.run.dir={run} ckpt_path=last" in lines[-1]

    saved = load_checkpoint(last)
    epoch, step = saved["epoch"], saved["global_step"]
    assert epoch >= 1 and step > per_epoch
    assert _adam_steps(saved) == {step}  # one Adam step per training step, none lost
    assert set(saved["callbacks"]["ResumeState"]["rng"]) >= {"python", "numpy", "torch"}
    phases_state = saved["callbacks"]["LossPhases"]
    assert phases_state["phases"] == PHASES and phases_state["unit"] == "epochs"
    # SIGTERM is acted on after a batch or at an epoch's end (then "epoch" is already the next one)
    assert phases_state["last_epoch"] in (epoch - 1, epoch)
    assert phases_state["current_phase"] == min(phases_state["last_epoch"], 2)

    # resume for two more epochs; the phase list on this command line differs on purpose: the
    # checkpoint's (restored) schedule must win
    total = (epoch + 2) * per_epoch
    res = subprocess.run([str(BIN / "lit3d-train"), *common, _phases_override([{"start": 0, "alpha": 1.0, "beta": 1.0}]),
                          f"trainer.max_epochs={epoch + 2}", "ckpt_path=last"],
                         cwd=REPO, env=child_env(), capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr[-3000:]
    assert "Restored all states from the checkpoint" in (run / "train.log").read_text()
    final = load_checkpoint(last)
    # written at the end of the last epoch by ModelCheckpoint(save_last) (its epoch counter has moved on)
    assert final["epoch"] in (epoch + 1, epoch + 2) and final["global_step"] == total
    assert _adam_steps(final) == {total}  # Adam continued from the saved state (else total - step)
    assert final["callbacks"]["LossPhases"]["phases"] == PHASES
    assert final["callbacks"]["LossPhases"]["last_epoch"] == epoch + 1
    # what the resumed process trained with: every step from the saved one on, each with the alpha/beta
    # of the saved phase list at its epoch (loss = alpha * depth + beta * mask)
    rows = [r for r in _csv_rows(run, 1) if r.get("train/loss_step")]
    assert [int(r["step"]) for r in rows] == list(range(step, total)), "resumed at another step"
    for r in rows:
        want = PHASES[min(int(r["epoch"]), 2)]
        expect = want["alpha"] * float(r["train/depth_loss_step"]) + want["beta"] * float(r["train/mask_loss_step"])
        assert float(r["train/loss_step"]) == pytest.approx(expect, rel=1e-4), (r, want)
    assert {int(r["epoch"]) for r in rows} == {epoch, epoch + 1}
    # one last.ckpt, shared by ResumeState and ModelCheckpoint(save_last=True): no last-v1.ckpt beside it
    assert sorted(p.name for p in (run / "checkpoints").glob("last*.ckpt")) == ["last.ckpt"]


# ----------------------------------------------------------------------------- Ctrl-C (SIGINT)
def test_ctrl_c_saves_last_and_says_how_to_resume(tmp_path, canonical_data):
    """Ctrl-C takes the SIGTERM path: ``last.ckpt`` saved, exit 143, one last line with
    the resume command, no Lightning "Detected KeyboardInterrupt"; ``ckpt_path=last`` resumes."""
    run = tmp_path / "run"
    common = [*CANONICAL, "data.batch_size=2", "logger=none", "callbacks.resume_state.every_n_train_batches=1",
              f"paths.data_dir={canonical_data}", f"hydra.run.dir={run}"]
    last = run / "checkpoints" / "last.ckpt"
    proc = start_script(["lit3d-train", *common, "trainer.max_epochs=500"], tmp_path / "first")
    _wait_for_checkpoint(proc, last, lambda c: c["global_step"] >= 3, tmp_path / "first")
    proc.send_signal(signal.SIGINT)
    assert proc.wait(timeout=120) == 143
    err = (tmp_path / "first.err").read_text()
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert "Traceback" not in err and "KeyboardInterrupt" not in err, err[-2000:]
    assert [ln for ln in lines if ln.startswith("error:")] == [lines[-1]], err[-2000:]
    assert lines[-1].startswith(f"error: {run}: stopped by SIGINT (Ctrl-C) at epoch ")
    assert f"hydra.run.dir={run} ckpt_path=last" in lines[-1]
    saved = load_checkpoint(last)
    assert saved["global_step"] >= 3 and _adam_steps(saved) == {saved["global_step"]}
    res = subprocess.run([str(BIN / "lit3d-train"), *common, f"trainer.max_epochs={saved['epoch'] + 1}",
                          "ckpt_path=last"], cwd=REPO, env=child_env(), capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr[-3000:]
    assert load_checkpoint(last)["global_step"] > saved["global_step"]


# ----------------------------------------------------------------------------- SIGKILL: completion GAN
@pytest.mark.slow
def test_sigkill_then_resume_continues_completion_gan(tmp_path):
    run = tmp_path / "run"
    common = [*COMPLETION, "logger=none", "callbacks.resume_state.every_n_train_batches=1",
              f"paths.data_dir={tmp_path}/data", f"hydra.run.dir={run}"]
    last = run / "checkpoints" / "last.ckpt"
    proc = start_script(["lit3d-train", *common, "trainer.max_epochs=200"], tmp_path / "first")
    _wait_for_checkpoint(proc, last, lambda c: c["epoch"] >= 1 and c["generator_steps"] > COMPLETION_BATCHES_PER_EPOCH,
                         tmp_path / "first")
    proc.send_signal(signal.SIGKILL)  # no handler, no final save: what survives is the last per-batch save
    assert proc.wait(timeout=60) == -signal.SIGKILL

    saved = load_checkpoint(last)
    epoch, batches = saved["epoch"], saved["generator_steps"]
    assert epoch >= 1 and batches > COMPLETION_BATCHES_PER_EPOCH
    assert saved["global_step"] == 2 * batches  # critic + generator step per batch
    assert _adam_steps(saved, 0) == {batches} and _adam_steps(saved, 1) == {batches}
    assert set(saved["callbacks"]["ResumeState"]["rng"]) >= {"python", "numpy", "torch"}

    total = (epoch + 2) * COMPLETION_BATCHES_PER_EPOCH
    res = subprocess.run([str(BIN / "lit3d-train"), *common, f"trainer.max_epochs={epoch + 2}", "ckpt_path=last"],
                         cwd=REPO, env=child_env(), capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr[-3000:]
    final = load_checkpoint(last)
    assert final["epoch"] in (epoch + 1, epoch + 2)  # end-of-epoch save_last: the counter may have moved on
    assert final["generator_steps"] == total and final["global_step"] == 2 * total
    assert _adam_steps(final, 0) == {total} and _adam_steps(final, 1) == {total}
    assert not list((run / "checkpoints").glob("*.tmp")), "a temp file of a cut save was left"


# ----------------------------------------------------------------------------- data preparation killed
@pytest.mark.slow  # default suite under 10 min; runs in make test-all
def test_killed_data_generation_keeps_finished_items_and_resumes_identically(tmp_path, compose_cfg, monkeypatch):
    import datamodules.completion.sources as completion_sources
    from datamodules.completion.voxel_cache import load_pair

    overrides = ["experiment=completion_demo", "data.prepare.progress=false",
                 "data.sizes={train:120,val:0,test_same:0,test_cross:0,test_unseen:0}"]
    data_dir = tmp_path / "data"
    items_dir = data_dir / "completion_demo" / "items"  # the demo's data_dir
    proc = start_script(["lit3d-data", *overrides, f"paths.data_dir={data_dir}", f"hydra.run.dir={tmp_path}/run"],
                  tmp_path / "data_cli")
    t0 = time.monotonic()
    while len(list(items_dir.rglob("*.npz"))) < 5:
        assert proc.poll() is None, (tmp_path / "data_cli.err").read_text()[-3000:]
        assert time.monotonic() - t0 < 180, "generation did not start"
        time.sleep(0.05)
    proc.send_signal(signal.SIGKILL)
    assert proc.wait(timeout=60) == -signal.SIGKILL
    assert not (data_dir / "completion_demo" / "manifest.json").exists(), "killed before the manifest"
    done = sorted(items_dir.rglob("*.npz"))
    assert 5 <= len(done) < 120
    for p in done:  # every item on disk is complete (temp file + rename); a cut write leaves only a .tmp
        load_pair(p)
    mtimes = {p: p.stat().st_mtime_ns for p in done}

    cfg = compose_cfg(overrides, data_dir=data_dir)
    dm = build_datamodule(cfg.data)
    real, calls = completion_sources.synth_pair, []
    monkeypatch.setattr(completion_sources, "synth_pair", lambda it, *a, **k: calls.append(it["file"]) or real(it, *a, **k))
    dm.prepare_data()
    assert len(calls) == 120 - len(done), "finished items were generated again"
    assert not {str(items_dir.parent / f) for f in calls} & {str(p) for p in done}
    assert {p: p.stat().st_mtime_ns for p in done} == mtimes, "finished items were rewritten"
    assert not list(items_dir.parent.rglob("*.tmp"))
    resumed = json.loads((items_dir.parent / "manifest.json").read_text())
    assert len(resumed["items"]) == 120

    monkeypatch.setattr(completion_sources, "synth_pair", real)
    fresh = build_datamodule(compose_cfg(overrides, data_dir=tmp_path / "fresh").data)
    fresh.prepare_data()
    fresh_manifest = json.loads((tmp_path / "fresh" / "completion_demo" / "manifest.json").read_text())
    assert resumed["manifest_hash"] == fresh_manifest["manifest_hash"]  # killed + resumed == uninterrupted


def test_canonical_cache_hash_is_the_same_in_another_process_and_differs_by_seed(tmp_path, canonical_data,
                                                                                compose_cfg):
    # the SIGTERM test (or this one) rendered canonical_data in its own process with seed 42
    dm = build_datamodule(compose_cfg(CANONICAL, data_dir=canonical_data).data)
    dm.prepare_data()
    shared = json.loads((canonical_data / "canonical_synth" / "manifest.json").read_text())
    here = build_datamodule(compose_cfg(CANONICAL, data_dir=tmp_path / "a").data)
    here.prepare_data()
    again = json.loads((tmp_path / "a" / "canonical_synth" / "manifest.json").read_text())
    assert again["complete"] and again["manifest_hash"] == shared["manifest_hash"]
    other = build_datamodule(compose_cfg([*CANONICAL, "seed=7"], data_dir=tmp_path / "b").data)
    other.prepare_data()
    differs = json.loads((tmp_path / "b" / "canonical_synth" / "manifest.json").read_text())
    assert differs["manifest_hash"] != shared["manifest_hash"]


# ----------------------------------------------------------------------------- NaN / Inf losses
def _overflowing(compose_cfg, canonical_data, mode: str, *extra: str):
    """Canonical training whose weighted loss overflows to Inf at the first step (alpha = 1e39 in float32)."""
    return compose_cfg([*CANONICAL, "logger=none", "task.phases.use=false", "task.phases.alpha=1e39",
                        f"task.on_nonfinite={mode}", "trainer.max_epochs=1", *extra], data_dir=canonical_data)


def test_nonfinite_loss_raise_stops_with_step_and_term(compose_cfg, canonical_data, capsys):
    cfg = _overflowing(compose_cfg, canonical_data, "raise")
    with pytest.raises(SystemExit) as info:
        run_cli(train, cfg)
    assert info.value.code == 1
    err = capsys.readouterr().err
    assert "Traceback" not in err
    errors = [ln for ln in err.splitlines() if ln.startswith("error:")]
    assert errors == ["error: non-finite loss at step 0 (epoch 0, batch 0): loss "
                      "(set task.on_nonfinite=skip to skip such steps)"], err


def test_nonfinite_loss_skip_counts_and_keeps_weights(compose_cfg, canonical_data):
    cfg = _overflowing(compose_cfg, canonical_data, "skip", "callbacks.resume_state.every_n_train_batches=1")
    run_cli(train, cfg)
    ckpt = load_checkpoint(Path(cfg.paths.output_dir) / "checkpoints" / "last.ckpt")
    assert ckpt["skipped_steps"] == CANONICAL_STEPS_PER_EPOCH  # every step overflowed, every one was skipped
    assert all(torch.isfinite(v).all() for v in ckpt["state_dict"].values()), "a skipped step changed the weights"


@pytest.mark.parametrize("target", ["lit3d.canonical.module.CanonicalTask", "lit3d.completion.module.CompletionTask"])
def test_unknown_nonfinite_mode_is_refused(target, completion_demo_nets):
    from lit3d.runtime.build import import_object

    kwargs = {"nets": completion_demo_nets} if "Completion" in target else {}
    with pytest.raises(ValueError, match="on_nonfinite must be one of"):
        import_object(target)(on_nonfinite="ignore", **kwargs)


# ----------------------------------------------------------------------------- RNG state in checkpoints
def test_resume_state_rng_round_trips_through_a_weights_only_checkpoint(tmp_path):
    """What ``ResumeState`` stores survives ``torch.load(weights_only=True)`` and restores the
    Python, NumPy and torch random streams exactly where they were saved."""
    import random

    import numpy as np

    from lit3d.callbacks.resume import ResumeState

    random.seed(1), np.random.seed(1), torch.manual_seed(1)
    torch.save({"callbacks": {"ResumeState": ResumeState(str(tmp_path)).state_dict()}}, tmp_path / "s.ckpt")
    expected = (random.random(), np.random.rand(3).tolist(), torch.rand(3).tolist())
    random.seed(2), np.random.seed(2), torch.manual_seed(2)  # a fresh process would start elsewhere
    state = load_checkpoint(tmp_path / "s.ckpt")["callbacks"]["ResumeState"]
    ResumeState(str(tmp_path)).load_state_dict(state)
    assert (random.random(), np.random.rand(3).tolist(), torch.rand(3).tolist()) == expected


def test_resume_state_counts_batches_across_epochs(tmp_path):
    """every_n_train_batches counts over the run: 3-batch epochs with N=4 save after batches 4 and 8."""
    from types import SimpleNamespace

    from lit3d.callbacks.resume import ResumeState

    saved = []
    trainer = SimpleNamespace(fast_dev_run=False, sanity_checking=False,
                              save_checkpoint=lambda path, **kwargs: saved.append(path))
    cb = ResumeState(str(tmp_path), every_n_train_batches=4)
    for _epoch in range(3):
        for batch_idx in range(3):
            cb.on_train_batch_end(trainer, None, None, None, batch_idx)
    assert len(saved) == 2 and cb.saves == 2
