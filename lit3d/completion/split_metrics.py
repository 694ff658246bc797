"""The completion test epoch's values: per test split and prediction source, the IoU at the
source's threshold (mean and pooled) and the cross-entropy, over all samples and per category.

Used by :meth:`lit3d.completion.module.CompletionTask.on_test_epoch_end`. Metrics are computed
through :func:`lit3d.metrics.gathered.compute_if_updated`, so under DDP every process computes
(and syncs) the same metrics even when one of them saw no batch of a split.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence

import torch

from lit3d.metrics.gathered import compute_if_updated
from lit3d.metrics.voxel import VoxelSweepMetrics


def threshold_index(grid: torch.Tensor, t: float) -> int:
    """Index of the threshold of ``grid`` nearest to ``t``."""
    return int(torch.argmin((grid - t).abs()))


def split_values(metrics: Mapping[str, VoxelSweepMetrics], splits: Sequence[str], sources: Sequence[str],
                 thresholds: Mapping[str, float], grid: torch.Tensor, categories: Sequence[str]) -> dict[str, float]:
    """``test/<split>/{iou,iou_pooled,ce}[_<source>][/<category>]`` of every ``metrics[f"{split}_{source}"]``
    (no suffix for ``model``), each metric reset afterwards.

    Args:
        metrics: the test metrics, keyed ``"<split>_<source>"``.
        thresholds: per source, the threshold its IoUs are read at (the nearest of ``grid``).
        grid: the metrics' threshold sweep.
        categories: the metrics' categories, in their order.
    A split the test data lacks (no update on any process, or no sample of a known category)
    gives no key.
    """
    out: dict[str, float] = {}
    for split in splits:
        for src in sources:
            metric = metrics[f"{split}_{src}"]
            res = compute_if_updated(metric)  # None: a split the test data lacks (e.g. no unseen categories)
            if res is None:
                continue
            if float(res["count_per_category"].sum()) == 0:
                metric.reset()
                continue
            j = threshold_index(grid, thresholds[src])
            suffix = "" if src == "model" else f"_{src}"
            out[f"test/{split}/iou{suffix}"] = float(res["iou"][j])
            out[f"test/{split}/iou_pooled{suffix}"] = float(res["iou_pooled"][j])
            out[f"test/{split}/ce{suffix}"] = float(res["ce"])
            for c, cat in enumerate(categories):
                if res["count_per_category"][c] > 0:
                    out[f"test/{split}/iou{suffix}/{cat}"] = float(res["iou_per_category"][c, j])
                    out[f"test/{split}/iou_pooled{suffix}/{cat}"] = float(res["iou_pooled_per_category"][c, j])
                    out[f"test/{split}/ce{suffix}/{cat}"] = float(res["ce_per_category"][c])
            metric.reset()
    return out
