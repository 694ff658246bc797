"""``lit3d-eval split=val``: the validation split's ``val/`` metrics of a checkpoint (settings chosen on
validation items, not on the test set), written as metrics.json and config.yaml; a split that is neither
test nor val is one line, exit 2."""
from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest
from tests.helpers.runs import BIN, REPO, TINY_NETS, child_env

from lit3d.api.checkpoints import untrained_checkpoint

SIZES = "data.sizes={train:2,val:2,test_same:2,test_cross:2,test_unseen:0}"


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("eval_split")
    return untrained_checkpoint("completion_demo", root / "c.ckpt", [*TINY_NETS, SIZES, "data.batch_size=2",
                                                                     "data.progress=false", f"paths.data_dir={root}/data"])


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
