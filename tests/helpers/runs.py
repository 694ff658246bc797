"""Running the console scripts as a user does, in a subprocess: the checkout (REPO), the venv's scripts (BIN),
the child environment (one thread, W&B offline), a background start, a checkpoint read, and the tiny
canonical and completion settings that keep a real run to seconds."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import torch

from tests.helpers.paths import REPO


BIN = Path(sys.executable).parent


# canonical demo at 32^2 with tiny nets: 6 subjects x 6 poses, 3 folds -> 16 train pairs = 4 batches
# (the old mixed validation rule, data.split.val_subjects=null, keeps 4 subjects for training)
CANONICAL = [
    "experiment=canonical_demo", "data.image_size=32", "data.source.n_subjects=6", "data.source.n_poses=6",
    "data.split.val_subjects=null",
    "data.source.mesh_resolution=20", "data.source.kinds=[humanoid]", "data.batch_size=4", "task.net.image_size=32",
    "task.net.lfe.channels=[8,12,16]", "task.net.msfe.channels=[6,6,4]", "task.net.msfe.grid=6",
    "task.net.msfe.fuser_hidden=64", "task.net.msfe.fuser_out=48", "task.net.msfe.dec_channels=[32,16,12,8,8,8]",
    "task.net.reconstruction.channels=[12,16,24]", "evaluation.retrieval=null",
    "evaluation.mesh_baselines=[]", "task.mask_loss=bce", "test_after_fit=false", "callbacks.progress_bar=null",
    "+trainer.limit_val_batches=0", "data.source.own_poses=0", "data.split.val_poses=training", "data.prepare_workers=0",
]


CANONICAL_STEPS_PER_EPOCH = 4


def child_env() -> dict:
    env = {k: v for k, v in os.environ.items() if k != "HYDRA_FULL_ERROR"}
    env.update(WANDB_MODE="offline", WANDB_SILENT="true", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")
    return env


def start_script(args: list[str], log: Path) -> subprocess.Popen:
    """A console script in the background, stdout/stderr into files (no pipe to fill up)."""
    with open(log.with_suffix(".out"), "w") as out, open(log.with_suffix(".err"), "w") as err:
        return subprocess.Popen([str(BIN / args[0]), *args[1:]], cwd=REPO, env=child_env(), stdout=out, stderr=err)


def load_checkpoint(path: Path) -> dict:
    return torch.load(path, map_location="cpu", weights_only=True)


TINY_NETS = ["task.nets.latent_dim=64", "task.nets.k=16", "task.nets.fixed_latent_dim=64", "task.prior_samples=2"]
