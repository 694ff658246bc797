"""One-pass IoU threshold sweep vs 17 separate binarisations (256^3 grids)."""
from __future__ import annotations

import torch

from benchmarks.common import median_time, row
from lit3d.metrics.voxel import default_thresholds, iou_at_thresholds


def seventeen_passes(probs: torch.Tensor, target: torch.Tensor, thresholds: torch.Tensor) -> torch.Tensor:
    """The straightforward baseline: binarise and count once per threshold."""
    y = target.reshape(target.shape[0], -1) > 0.5
    p = probs.reshape(probs.shape[0], -1)
    out = []
    for t in thresholds.tolist():
        pred = p >= t
        inter = (pred & y).sum(1)
        union = (pred | y).sum(1)
        out.append(inter.double() / union.clamp_min(1).double())
    return torch.stack(out, 1)


def run() -> list[dict]:
    g = torch.Generator().manual_seed(0)
    res, batch = 256, 3
    probs = torch.rand(batch, 1, res, res, res, generator=g)
    target = (torch.rand(batch, 1, res, res, res, generator=g) < 0.2).float()
    thr = default_thresholds()
    ours = median_time(lambda: iou_at_thresholds(probs, target, thr), repeats=3)
    base = median_time(lambda: seventeen_passes(probs, target, thr), repeats=3)
    assert torch.allclose(iou_at_thresholds(probs, target, thr), seventeen_passes(probs, target, thr.float()), atol=1e-6)
    return [row("IoU threshold sweep, 17 thresholds, batch 3 x 256^3", "make bench", ours, base,
                note="target >= 5x", baseline_name="17 passes")]
