"""Small canonical-task inputs for tests: a toy subject batch, a tiny net, one training step's losses, and
the pooled cross-validation's data module and fold outputs."""
from __future__ import annotations

import torch
from omegaconf import OmegaConf

from datamodules.canonical import CanonicalDataModule
from lit3d.canonical.module import CanonicalTask


def square_subjects(n: int = 8, size: int = 32, classes: int = 4):
    """A toy subject-recognition batch: ``(depth (n,1,size,size), mask, subject_idx (n,))``, subject k a
    filled square of side 6 + 3k (depth .5) at a random place (seeded): what tells them apart is the size."""
    import torch

    g = torch.Generator().manual_seed(0)
    depth, idx = torch.zeros(n, 1, size, size), torch.arange(n) % classes
    for i in range(n):
        s = 6 + 3 * int(idx[i])
        x, y = torch.randint(0, size - s, (2,), generator=g).tolist()
        depth[i, 0, y:y + s, x:x + s] = 0.5
    return depth, (depth > 0).float(), idx


def tiny_canonical_net(compose_cfg, size=32):
    cfg = compose_cfg(["experiment=canonical_tiny", f"task.net.image_size={size}"])
    return OmegaConf.to_container(cfg.task.net, resolve=True)


def subject_batch(n=8, size=32, classes=4):
    """Subjects told apart by size (:func:`conftest.square_subjects`); the target is the input."""
    depth, mask, idx = square_subjects(n, size, classes)
    return {"depth": depth, "mask": mask, "canon_depth": depth.clone(), "canon_mask": mask.clone(),
            "subject_idx": idx}


def step_losses(compose_cfg, batch, weights, **task_kw):
    """``({weight: training_step loss}, the last task)``: one task per weight (``task_kw``: objective nodes, one
    of which names the weight with ``{w}``), same seed, the same batch."""
    losses = {}
    for w in weights:
        torch.manual_seed(0)
        task = CanonicalTask(net=tiny_canonical_net(compose_cfg), mask_loss="bce", phases={"use": False},
                             **{k: {f: (w if v == "{w}" else v) for f, v in node.items()} for k, node in task_kw.items()})
        task.log = lambda *a, **k: None  # no trainer here: logging is not what these tests check
        losses[w] = task.training_step(batch, 0)
    return losses, task


RETRIEVAL = {"level": 0, "view_size": 32, "vocab": 16, "dense_step": 6}


def pooled_datamodule(tmp_path, fold=0, **kw):
    args = dict(image_size=32, n_subjects=4, n_poses=3, mesh_resolution=16, n_folds=3, batch_size=4,
                kinds=["humanoid", "quadruped"], seed=1, split="pose", val_per_subject=1, fold=fold)
    args.update(kw)
    dm = CanonicalDataModule.from_flat(str(tmp_path / "data"), **args)
    dm.prepare_data()
    dm.setup()
    return dm


def fold_outputs(dm):
    """What CanonicalTask.test_outputs gathers, with the posed input as the 'prediction'."""
    ds = dm.datasets["test"]
    items = [ds[i] for i in range(len(ds))]
    t = lambda k: torch.stack([it[k] for it in items])  # noqa: E731
    out = {k: t(k) for k in ("depth", "mask", "canon_depth", "canon_mask")}
    out.update(pred_depth=out["depth"], pred_mask=out["mask"])
    for k in ("subject_idx", "pose", "view", "index"):
        out[k] = torch.tensor([it[k] for it in items])
    return out
