"""Voxel occupancy metrics: IoU over a threshold sweep in one pass, and cross-entropy.

The thesis picks the threshold that maximises IoU on the validation set among
``0.10, 0.15, ..., 0.90`` and applies it to the test set. Instead of 17 passes
(one binarisation per threshold) we bucket every probability once into the
threshold bins and read all 17 confusion counts off cumulative sums:

    #(p >= t_j)        = sum of voxel counts in bins >= j
    #(p >= t_j, y = 1) = sum of occupied-voxel counts in bins >= j

so one ``torch.bucketize`` + ``bincount`` per batch gives the IoU at every
threshold. States are per category so that one metric object serves the
per-category tables, and they reduce with ``sum`` under DDP.
"""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch
from torchmetrics import Metric

EPS = 1e-7
# voxels per bucketize/bincount call: keeps the int32 keys in cache (1M = 4 MB)
CHUNK = 1 << 20


def occupancy_iou(a: np.ndarray, b: np.ndarray) -> float:
    """Intersection over union of two boolean grids of one shape (0 when both are empty)."""
    union = np.logical_or(a, b).sum()
    return float(np.logical_and(a, b).sum() / union) if union else 0.0


def default_thresholds() -> torch.Tensor:
    """The thesis's threshold grid 0.10, 0.15, ..., 0.90 (17 values), float64."""
    return torch.round(torch.arange(0.10, 0.90 + 1e-9, 0.05, dtype=torch.float64) * 100) / 100


def confusion_at_thresholds(
    probs: torch.Tensor, target: torch.Tensor, thresholds: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Per-sample counts for every threshold in one pass.

    Args:
        probs: (B, ...) occupancy probabilities in [0, 1], any float dtype.
        target: (B, ...) ground truth, {0, 1} (any dtype).
        thresholds: (T,) ascending thresholds; a voxel is predicted occupied when p >= t.

    Returns:
        predicted (B, T) int64: #(p >= t), true_pos (B, T) int64: #(p >= t and y = 1),
        positives (B,) int64: #(y = 1).
    """
    b = probs.shape[0]
    p = probs.reshape(b, -1).float()
    y = target.reshape(b, -1) > 0.5
    thr = thresholds.to(p.device, torch.float32)
    n_bins = thr.numel() + 1
    # Bin j holds t_{j-1} <= p < t_j (right=True puts p == t_j into bin j+1, i.e. p >= t_j);
    # occupied voxels use bins n_bins..2*n_bins-1, so one bincount gives both histograms.
    counts = torch.zeros(b, 2 * n_bins, dtype=torch.int64, device=p.device)
    for i in range(b):
        for s in range(0, p.shape[1], CHUNK):
            key = torch.bucketize(p[i, s:s + CHUNK], thr, right=True, out_int32=True)
            key += y[i, s:s + CHUNK].to(torch.int32) * n_bins
            counts[i] += torch.bincount(key, minlength=2 * n_bins)
    pos_counts = counts[:, n_bins:]
    all_counts = counts[:, :n_bins] + pos_counts
    # counts at or above bin j, for j = 1..T  (bin 0 is p < t_0)
    predicted = all_counts.flip(1).cumsum(1).flip(1)[:, 1:]
    true_pos = pos_counts.flip(1).cumsum(1).flip(1)[:, 1:]
    return predicted, true_pos, y.sum(1)


def iou_at_thresholds(probs: torch.Tensor, target: torch.Tensor, thresholds: torch.Tensor) -> torch.Tensor:
    """Per-sample IoU at every threshold, (B, T) float64.

    An empty prediction of an empty target counts as IoU 1.
    """
    predicted, true_pos, positives = confusion_at_thresholds(probs, target, thresholds)
    union = predicted + positives.unsqueeze(1) - true_pos
    iou = true_pos.double() / union.clamp_min(1).double()
    return torch.where(union == 0, torch.ones_like(iou), iou)


def voxel_cross_entropy(probs: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """Per-sample mean binary cross-entropy of probabilities, (B,) float64.

    Args:
        probs: (B, ...) probabilities in [0, 1]; clamped to [1e-7, 1 - 1e-7].
        target: (B, ...) {0, 1}.
    """
    b = probs.shape[0]
    p = probs.reshape(b, -1).double().clamp(EPS, 1 - EPS)
    y = target.reshape(b, -1).double()
    return -(y * p.log() + (1 - y) * (1 - p).log()).mean(1)


class VoxelSweepMetrics(Metric):
    """Mean per-sample IoU and pooled IoU at every threshold, and mean CE, per category.

    ``update(probs, target, category)`` with probs/target (B, 1, D, H, W) and
    category (B,) int64 indices into ``categories`` (out-of-range -> ignored).
    ``compute()`` returns a dict:
        ``iou`` (T,) mean IoU over all samples at each threshold,
        ``iou_per_category`` (C, T), ``iou_pooled`` (T,) pooled IoU (sum of the samples'
        intersections / sum of their unions: big shapes weigh more; the thesis does not say
        which of the two it reports), ``iou_pooled_per_category`` (C, T),
        ``ce`` scalar, ``ce_per_category`` (C,),
        ``count_per_category`` (C,).
    Categories with no samples get NaN in the per-category tensors.
    """

    full_state_update = False
    higher_is_better = True

    def __init__(self, categories: Sequence[str], thresholds: torch.Tensor | None = None, **kwargs):
        super().__init__(**kwargs)
        self.categories = list(categories)
        thr = default_thresholds() if thresholds is None else torch.as_tensor(thresholds, dtype=torch.float64)
        self.register_buffer("thresholds", thr.float(), persistent=False)
        c, t = len(self.categories), thr.numel()
        self.add_state("iou_sum", torch.zeros(c, t, dtype=torch.float64), dist_reduce_fx="sum")
        self.add_state("inter_sum", torch.zeros(c, t, dtype=torch.float64), dist_reduce_fx="sum")
        self.add_state("union_sum", torch.zeros(c, t, dtype=torch.float64), dist_reduce_fx="sum")
        self.add_state("ce_sum", torch.zeros(c, dtype=torch.float64), dist_reduce_fx="sum")
        self.add_state("count", torch.zeros(c, dtype=torch.float64), dist_reduce_fx="sum")

    def update(self, probs: torch.Tensor, target: torch.Tensor, category: torch.Tensor) -> None:
        category = category.to(self.count.device).long()
        keep = (category >= 0) & (category < len(self.categories))
        if not bool(keep.any()):
            return
        probs, target, category = probs[keep], target[keep], category[keep]
        predicted, true_pos, positives = confusion_at_thresholds(probs, target, self.thresholds)
        union = (predicted + positives.unsqueeze(1) - true_pos).double()
        iou = torch.where(union == 0, torch.ones_like(union), true_pos.double() / union.clamp_min(1))
        ce = voxel_cross_entropy(probs, target)
        self.iou_sum.index_add_(0, category, iou)
        self.inter_sum.index_add_(0, category, true_pos.double())
        self.union_sum.index_add_(0, category, union)
        self.ce_sum.index_add_(0, category, ce)
        self.count.index_add_(0, category, torch.ones_like(ce))

    def compute(self) -> dict[str, torch.Tensor]:
        total = self.count.sum().clamp_min(1)
        per_count = self.count.unsqueeze(1)
        nan = torch.tensor(float("nan"), dtype=torch.float64, device=self.count.device)
        return {
            "iou": self.iou_sum.sum(0) / total,
            "iou_per_category": torch.where(per_count > 0, self.iou_sum / per_count.clamp_min(1), nan),
            "iou_pooled": _pooled(self.inter_sum.sum(0), self.union_sum.sum(0)),
            "iou_pooled_per_category": torch.where(per_count > 0, _pooled(self.inter_sum, self.union_sum), nan),
            "ce": self.ce_sum.sum() / total,
            "ce_per_category": torch.where(self.count > 0, self.ce_sum / self.count.clamp_min(1), nan),
            "count_per_category": self.count,
        }


def _pooled(inter: torch.Tensor, union: torch.Tensor) -> torch.Tensor:
    """Pooled IoU = summed intersections / summed unions (1 where both sums are 0)."""
    return torch.where(union > 0, inter / union.clamp_min(1), torch.ones_like(union))


def best_threshold(iou_curve: torch.Tensor, thresholds: torch.Tensor) -> tuple[float, float]:
    """(threshold, IoU) maximising a (T,) IoU curve; the lowest threshold wins ties."""
    j = int(torch.argmax(iou_curve))
    return float(thresholds[j]), float(iou_curve[j])
