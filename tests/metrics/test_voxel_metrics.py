"""Voxel IoU sweep and CE against brute-force references."""
import math

import numpy as np
import pytest
import torch

from lit3d.metrics.voxel import (
    VoxelSweepMetrics,
    best_threshold,
    default_thresholds,
    iou_at_thresholds,
    voxel_cross_entropy,
)


def brute_iou(p: np.ndarray, y: np.ndarray, t: float) -> float:
    pred = p >= t
    inter = np.logical_and(pred, y).sum()
    union = np.logical_or(pred, y).sum()
    return 1.0 if union == 0 else inter / union


def test_threshold_grid_is_thesis_grid():
    thr = default_thresholds()
    assert thr.numel() == 17
    assert thr[0].item() == pytest.approx(0.10) and thr[-1].item() == pytest.approx(0.90)


def test_one_pass_sweep_equals_brute_force_at_every_threshold():
    g = torch.Generator().manual_seed(0)
    probs = torch.rand(5, 1, 12, 12, 12, generator=g)
    # put probabilities exactly on thresholds too (ties must count as >= t)
    probs[0, 0, 0, :, :] = 0.35
    target = (torch.rand(5, 1, 12, 12, 12, generator=g) < 0.3).float()
    thr = default_thresholds()
    got = iou_at_thresholds(probs, target, thr)
    for b in range(5):
        for j, t in enumerate(thr.tolist()):
            # compare in float32 as the metric does
            ref = brute_iou(probs[b].numpy(), target[b].numpy() > 0.5, np.float32(t))
            assert got[b, j].item() == pytest.approx(ref, abs=1e-12)


def test_empty_prediction_of_empty_target_is_one():
    probs = torch.zeros(1, 1, 4, 4, 4)
    target = torch.zeros(1, 1, 4, 4, 4)
    assert torch.all(iou_at_thresholds(probs, target, default_thresholds()) == 1)


def test_cross_entropy_matches_torch():
    g = torch.Generator().manual_seed(1)
    probs = torch.rand(3, 1, 6, 6, 6, generator=g).clamp(0.01, 0.99)
    target = (torch.rand(3, 1, 6, 6, 6, generator=g) < 0.5).float()
    ref = torch.nn.functional.binary_cross_entropy(probs.double(), target.double(), reduction="none")
    assert torch.allclose(voxel_cross_entropy(probs, target), ref.reshape(3, -1).mean(1))


def test_metric_per_category_and_best_threshold():
    g = torch.Generator().manual_seed(2)
    m = VoxelSweepMetrics(["a", "b", "c"])
    probs = torch.rand(6, 1, 8, 8, 8, generator=g)
    target = (probs + 0.2 * torch.rand(6, 1, 8, 8, 8, generator=g) > 0.7).float()
    cats = torch.tensor([0, 0, 1, 1, 1, -1])  # last sample ignored
    m.update(probs[:3], target[:3], cats[:3])
    m.update(probs[3:], target[3:], cats[3:])
    out = m.compute()
    thr = default_thresholds()
    full = iou_at_thresholds(probs[:5], target[:5], thr)
    assert torch.allclose(out["iou"], full.mean(0))
    assert torch.allclose(out["iou_per_category"][0], full[:2].mean(0))
    assert torch.allclose(out["iou_per_category"][1], full[2:5].mean(0))
    assert math.isnan(out["iou_per_category"][2, 0].item())
    assert out["count_per_category"].tolist() == [2, 3, 0]
    t, best = best_threshold(out["iou"], thr)
    brute = [np.mean([brute_iou(probs[b].numpy(), target[b].numpy() > 0.5, np.float32(tt)) for b in range(5)])
             for tt in thr.tolist()]
    assert best == pytest.approx(max(brute))
    assert t == pytest.approx(thr[int(np.argmax(brute))].item())


def test_pooled_iou_is_summed_intersections_over_summed_unions():
    from lit3d.metrics.voxel import VoxelSweepMetrics

    g = torch.Generator().manual_seed(4)
    probs = torch.rand(5, 1, 6, 6, 6, generator=g)
    target = (torch.rand(5, 1, 6, 6, 6, generator=g) > 0.7).float()
    target[0] = 0.0  # an empty target: counts in the sums, not as a per-sample 1
    probs[0] = 0.0
    cats = torch.tensor([0, 0, 1, 1, 1])
    m = VoxelSweepMetrics(["a", "b"])
    m.update(probs[:2], target[:2], cats[:2])
    m.update(probs[2:], target[2:], cats[2:])
    res = m.compute()
    for j, t in enumerate(m.thresholds.tolist()):
        p = probs.numpy() >= t
        y = target.numpy() > 0.5
        inter, union = (p & y).reshape(5, -1).sum(1), (p | y).reshape(5, -1).sum(1)
        assert float(res["iou_pooled"][j]) == pytest.approx(inter.sum() / union.sum())
        for c in (0, 1):
            k = cats.numpy() == c
            assert float(res["iou_pooled_per_category"][c, j]) == pytest.approx(inter[k].sum() / union[k].sum())
        per_sample = np.where(union == 0, 1.0, inter / np.maximum(union, 1))
        assert float(res["iou"][j]) == pytest.approx(per_sample.mean())
