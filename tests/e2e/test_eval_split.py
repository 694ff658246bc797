"""``lit3d-eval split=val``: the validation split's ``val/`` metrics of a checkpoint (settings chosen on
validation items, not on the test set), written as metrics.json and config.yaml, and for the canonical task
the validation items' predictions as heldout.npz, which ``lit3d-summary --pooled`` scores; a split that is
neither test nor val is one line, exit 2."""
from __future__ import annotations

import json
import subprocess
from pathlib import Path

import numpy as np
import pytest
import torch
from tests.helpers.runs import BIN, REPO, TINY_NETS, child_env

from lit3d.api.checkpoints import untrained_checkpoint
from lit3d.canonical.heldout import load_heldout
from lit3d.canonical.module import CanonicalTask
from lit3d.runtime.build import build_datamodule
from lit3d.runtime.checkpoints import read_checkpoint

SIZES = "data.sizes={train:2,val:2,test_same:2,test_cross:2,test_unseen:0}"


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("eval_split")
    overrides = [*TINY_NETS, SIZES, "data.batch_size=2", "data.prepare.progress=false", f"paths.data_dir={root}/data"]
    return untrained_checkpoint("completion_demo", root / "c.ckpt", overrides)


def _eval(args: list[str], timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run([str(BIN / "lit3d-eval"), *args], cwd=REPO, env=child_env(), capture_output=True, text=True,
                          timeout=timeout)


@pytest.mark.slow
def test_split_val_writes_the_validation_metrics_only(checkpoint, tmp_path):
    run = tmp_path / "val"
    res = _eval([f"ckpt_path={checkpoint}", "split=val", f"hydra.run.dir={run}"])
    assert res.returncode == 0, res.stderr[-3000:]
    metrics = json.loads((run / "metrics.json").read_text())
    assert metrics["split"] == "val" and metrics["ckpt_path"] == str(checkpoint)
    scores = [k for k in metrics if "/" in k]
    assert scores and all(k.startswith("val/") for k in scores), scores
    assert (run / "config.yaml").is_file() and not (run / "results.md").exists()


def test_a_split_other_than_test_or_val_is_one_line(tmp_path):
    ckpt = tmp_path / "c.ckpt"  # refused before the checkpoint is read
    res = _eval([f"ckpt_path={ckpt}", "split=train", f"hydra.run.dir={tmp_path / 'run'}"])
    assert res.returncode == 2 and res.stderr.strip().splitlines() == ["error: split=train: expected one of test, val"], \
        res.stderr[-3000:]
    assert not (tmp_path / "run" / "metrics.json").exists()


@pytest.fixture(scope="module")
def canonical_checkpoint(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("eval_split_canonical")
    return untrained_checkpoint("canonical_tiny", root / "c.ckpt", [
        "data.source.n_subjects=6", "data.source.n_poses=4", "data.image_size=32", "task.net.image_size=32",
        f"data.data_dir={root}/data"])


@pytest.mark.slow
def test_split_val_saves_the_canonical_validation_predictions_for_the_pooled_summary(canonical_checkpoint, tmp_path):
    run = tmp_path / "val"
    res = _eval([f"ckpt_path={canonical_checkpoint}", "split=val", f"hydra.run.dir={run}"])
    assert res.returncode == 0, res.stderr[-3000:]
    held = load_heldout(run)
    assert int(held["fold"]) == 0 and int(held["n_folds"]) == 1
    # the validation items, each once (not the test items), and the checkpoint's predictions of them
    ckpt, meta = read_checkpoint(canonical_checkpoint)
    dm = build_datamodule(meta["data"])
    dm.setup("validate")
    val = dm.datasets["val"]
    ids = sorted(f"{r['subject']}/{int(r['pose'])}/{r['view']}" for r in val.records)
    assert sorted(held["item"].tolist()) == ids == held["expected"].tolist()
    test_ids = {f"{r['subject']}/{int(r['pose'])}/{r['view']}" for r in dm.datasets["test"].records}
    assert not test_ids & set(ids)
    task = CanonicalTask.load_from_checkpoint(str(canonical_checkpoint), map_location="cpu")
    task.eval()
    batch = next(iter(dm.val_dataloader()))
    with torch.no_grad():
        pred = task(batch["depth"], batch["mask"])
    first = f"{batch['subject'][0]}/{int(batch['pose'][0])}/{int(batch['view'][0])}"
    at = held["item"].tolist().index(first)
    assert np.allclose(held["pred_depth"][at].astype(np.float32), pred.depth[0, 0].numpy(), atol=2e-3)
    out = tmp_path / "pooled"
    summary = subprocess.run([str(BIN / "lit3d-summary"), "--pooled", str(run), "--seeds", "0", "--out", str(out)],
                             cwd=REPO, env=child_env(), capture_output=True, text=True, timeout=600)
    assert summary.returncode == 0, summary.stderr[-3000:]
    assert "model" in (out / "pooled_results.md").read_text()
