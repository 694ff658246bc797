"""Tiny completion nets and grids shared by the step-cost, options and step-switch tests."""
from __future__ import annotations

from pathlib import Path

import torch

from lit3d.api.checkpoints import untrained_checkpoint
from lit3d.completion.checkpoint_upgrade import upgrade_hparams
from lit3d.completion.module import CompletionTask
from lit3d.runtime.build import build_datamodule
from lit3d.runtime.checkpoints import read_checkpoint_meta
from tests.helpers.runs import TINY_NETS

# two training items, four validation and four of each seen test split: an evaluation in seconds
TINY_SIZES = "data.sizes={train:2,val:4,test_same:4,test_cross:4,test_unseen:0}"


def tiny_nets(demo: dict) -> dict:
    """The demo nets shrunk: 8^3 -> 32^3, small latent, 4-layer critic (attention at 8^3)."""
    return {**demo, "in_res": 8, "out_res": 32, "enc_channels": [8, 16], "latent_dim": 64, "k": 16,
            "fixed_latent_dim": 64, "critic_channels": [8, 8, 8, 8], "critic_attention_res": 8}


def grid_pair(batch: int = 2, seed: int = 0) -> tuple[torch.Tensor, torch.Tensor]:
    """``(partial (B, 1, 8, 8, 8), target (B, 1, 32, 32, 32))`` float occupancy: a random target and its
    4x max-pooled input."""
    g = torch.Generator().manual_seed(seed)
    y = (torch.rand(batch, 1, 32, 32, 32, generator=g) < 0.2).float()
    return torch.nn.functional.max_pool3d(y, 4), y


def tiny_task(nets: dict, **kw) -> CompletionTask:
    """A :class:`CompletionTask` of :func:`tiny_nets` (``nets``: the demo's node), seeded; ``kw``: its settings,
    also by their short flat names (``gp_every=2``: :func:`lit3d.completion.checkpoint_upgrade.upgrade_hparams`)."""
    torch.manual_seed(0)
    return CompletionTask(**upgrade_hparams({"nets": tiny_nets(nets), **kw}))


def prepared_tiny_checkpoint(root: Path) -> Path:
    """An untrained tiny completion checkpoint in ``root`` whose data config (prepared here, under
    ``root/data``) is the one ``lit3d-eval`` evaluates."""
    ckpt = untrained_checkpoint("completion_demo", root / "c.ckpt", [*TINY_NETS, TINY_SIZES, "data.batch_size=2",
                                                                     "data.prepare.progress=false",
                                                                     f"paths.data_dir={root}/data"])
    build_datamodule(read_checkpoint_meta(ckpt)["data"]).prepare_data()
    return ckpt
