"""A quiet console: tiny runs of the entry points print no warning and none of the known noisy lines.

Each run goes through the console script, as a user runs it, with the default W&B logger (offline)
and the checkpoint callbacks; what the process prints (stdout and stderr) is checked for:

- Python warnings: Lightning and the standard library print them as ``<file>.py:<line>: <message>``;
- Lightning's "`weights_only` was not set" line (one per ``last.ckpt`` save before the fix);
- torchmetrics' "compute ... called before ... update" (a test split without data);
- Lightning's "Tip: ... litlogger" advertisement;
- W&B's "The anonymous setting has no effect";
- a traceback.
"""
from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh
from tests.helpers.paths import REPO

NOISE = {
    "python warning": re.compile(r"\.py:\d+: "),
    "weights_only": re.compile(r"weights_only"),
    "compute before update": re.compile(r"compute.*called before.*update"),
    "advertisement": re.compile(r"Tip: |litlogger|litmodels"),
    "deprecated W&B setting": re.compile(r"anonymous setting"),
    "traceback": re.compile(r"Traceback"),
}
# completion at demo net sizes with tiny latents; no unseen test data, so that split's metrics see no
# batch; last.ckpt saved after every training batch (the per-save line of the old ResumeState)
COMPLETION = ["experiment=completion_demo", "data.sizes={train:4,val:2,test_same:2,test_cross:2,test_unseen:0}",
              "data.batch_size=2", "task.nets.latent_dim=64", "task.nets.k=16", "task.nets.fixed_latent_dim=64",
              "task.prior_samples=2", "trainer.max_epochs=2", "trainer.log_every_n_steps=1",
              "callbacks.resume_state.every_n_train_batches=1"]
CANONICAL = ["experiment=canonical_tiny", "data.source.n_subjects=4", "data.source.n_poses=4", "data.split.val_subjects=null",
             "data.image_size=32", "task.net.image_size=32", "data.batch_size=4", "evaluation.mesh_baselines=[posed]",
             "evaluation.retrieval.view_size=32", "trainer.max_epochs=1", "trainer.log_every_n_steps=1",
             "callbacks.resume_state.every_n_train_batches=1"]


def _console(args: list[str], tmp_path: Path) -> str:
    env = {k: v for k, v in os.environ.items() if not k.startswith("WANDB_")}  # as a user's shell
    env.update(WANDB_MODE="offline", LIT3D_CACHE=str(tmp_path / "cache"))
    res = subprocess.run(args, cwd=REPO, env=env, capture_output=True, text=True, timeout=600)
    out = res.stdout + res.stderr
    assert res.returncode == 0, out[-4000:]
    return out


def _assert_quiet(out: str) -> None:
    lines = out.splitlines()
    found = {name: [ln for ln in lines if pat.search(ln)] for name, pat in NOISE.items()}
    found = {k: v for k, v in found.items() if v}
    assert not found, "\n".join(f"{k} ({len(v)} lines), first: {v[0][:300]}" for k, v in found.items())


def _bin(name: str) -> str:
    return str(Path(sys.executable).parent / name)


@pytest.mark.parametrize("task,overrides", [pytest.param("completion", COMPLETION, marks=pytest.mark.slow),  # 17 s
                                            ("canonical", CANONICAL)])
def test_train_console_is_quiet(task, overrides, tmp_path):
    run = tmp_path / "run"
    out = _console([_bin("lit3d-train"), *overrides, f"hydra.run.dir={run}", f"paths.data_dir={tmp_path / 'data'}"],
                   tmp_path)
    assert (run / "metrics.json").is_file() and (run / "checkpoints" / "last.ckpt").is_file()
    assert (run / "wandb").is_dir()  # the W&B logger was on
    _assert_quiet(out)


def test_score_console_is_quiet(tmp_path):
    ref = trimesh.creation.icosphere(3)
    dist = ref.copy()
    dist.vertices = dist.vertices + dist.vertex_normals * np.random.default_rng(0).normal(0, 0.02, (len(ref.vertices), 1))
    ref.export(tmp_path / "ref.obj")
    dist.export(tmp_path / "dist.obj")
    out = _console([_bin("lit3d-score"), str(tmp_path / "ref.obj"), str(tmp_path / "dist.obj"), "--size", "64",
                    "--styles", "toon,jade", "--save-views", str(tmp_path / "views")], tmp_path)
    assert "overall score" in out
    _assert_quiet(out)


def test_known_filters_are_few_and_explained():
    """The one place for warnings lit3d cannot fix: every filter says why."""
    from lit3d.utils import quiet

    entries = [*quiet.WARNING_FILTERS, *quiet.LOG_FILTERS, *quiet.LOG_LEVELS]
    assert 0 < len(entries) <= 6
    assert all(isinstance(e[-1], str) and len(e[-1]) > 40 for e in entries)
