"""The completion test epoch's surface metrics (:mod:`lit3d.metrics.surface`): per test split and
prediction source, Chamfer-L1, F-score at fractions of the target's bounding-box diagonal and
normal consistency of the thresholded prediction's marching-cubes surface against the target's.

Sizes come from the evaluation setting ``evaluation.surface`` (``conf/task/completion.yaml``): ``points``
sampled on each surface, ``fscore_at`` fractions, ``seed``. Each target is sampled once and shared by the
prediction sources; a grid that repeats (the prior's) is sampled once. Keys (no suffix for
``model``, ``_<source>`` for the baselines):
``test/<split>/{chamfer_l1,fscore_<f>pct,normal_consistency}[_<source>][/<category>]`` and
``test/<split>/surface_empty[_<source>]`` (predictions with no occupied voxel).
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import torch

from lit3d.metrics.gathered import compute_if_updated
from lit3d.metrics.surface import SurfaceMetrics, SurfaceSample, fscore_key, sample_grids

CACHE_SIZE = 8  # surface samples kept by grid content


class SurfaceTestMetrics(torch.nn.Module):
    """One :class:`SurfaceMetrics` per ``"<split>_<source>"`` (states reduced with ``sum`` under DDP).

    Args:
        splits, sources: test split and prediction source names.
        categories: the metrics' categories, in their order.
        points, fscore_at, seed: ``evaluation.surface`` (see the module doc).
    """

    def __init__(self, splits: Sequence[str], sources: Sequence[str], categories: Sequence[str], points: int,
                 fscore_at: Sequence[float], seed: int = 0):
        super().__init__()
        self.splits, self.sources, self.categories = tuple(splits), tuple(sources), list(categories)
        self.metrics = torch.nn.ModuleDict({f"{sp}_{s}": SurfaceMetrics(categories, points, fscore_at, seed)
                                            for sp in self.splits for s in self.sources})
        self.points, self.seed = int(points), int(seed)
        self._cache: dict[tuple, SurfaceSample | None] = {}

    def update(self, split: str, preds: Mapping[str, torch.Tensor], target: torch.Tensor, category: torch.Tensor,
               thresholds: Mapping[str, float]) -> None:
        """``preds[src]``: ``(B, 1, R, R, R)`` probabilities, occupied where ``>= thresholds[src]``
        (as the IoU reads them); ``target``: ``(B, 1, R, R, R)`` {0, 1}; ``category``: ``(B,)`` indices."""
        target_samples = self._samples(target > 0.5)
        for src in self.sources:
            occupied = self._samples(preds[src] >= thresholds[src])
            self.metrics[f"{split}_{src}"].update(occupied, target_samples, category)

    def _samples(self, occupied: torch.Tensor) -> list[SurfaceSample | None]:
        """Surface samples of ``(B, 1, R, R, R)`` bool grids; a grid seen in the last few calls (the
        prior baseline predicts one grid for every sample) is sampled once."""
        out = []
        for grid in occupied.detach().cpu().numpy():
            key = (grid.shape, hash(np.packbits(grid).tobytes()))
            if key not in self._cache:
                if len(self._cache) >= CACHE_SIZE:
                    self._cache.pop(next(iter(self._cache)))  # the oldest
                self._cache[key] = sample_grids(grid[None], self.points, self.seed)[0]
            out.append(self._cache[key])
        return out

    def values(self) -> dict[str, float]:
        """The keys of the module doc for every split and source some process updated; metrics reset."""
        return surface_values(self.metrics, self.splits, self.sources, self.categories)


def surface_values(metrics: Mapping[str, SurfaceMetrics], splits: Sequence[str], sources: Sequence[str],
                   categories: Sequence[str]) -> dict[str, float]:
    """The module doc's keys of every ``metrics[f"{split}_{source}"]`` (computed on every process
    through :func:`compute_if_updated`, so a process without a batch of a split still syncs), each
    metric reset afterwards. A split without scored samples gives no key."""
    out: dict[str, float] = {}
    for split in splits:
        for src in sources:
            metric = metrics[f"{split}_{src}"]
            res = compute_if_updated(metric)
            if res is None or float(res["count_per_category"].sum()) == 0:
                metric.reset()
                continue
            suffix = "" if src == "model" else f"_{src}"
            count = res["count_per_category"].reshape(-1)  # torchmetrics squeezes one-element results
            names = [(f"chamfer_l1{suffix}", "chamfer_l1", 0), (f"normal_consistency{suffix}", "normal_consistency", 0)]
            names += [(f"{fscore_key(f)}{suffix}", "fscore", j) for j, f in enumerate(metric.fscore_at)]
            for key, field, j in names:
                total, per = res[field].reshape(-1), res[f"{field}_per_category"].reshape(len(categories), -1)
                out[f"test/{split}/{key}"] = float(total[j])
                for c, cat in enumerate(categories):
                    if count[c] > 0:
                        out[f"test/{split}/{key}/{cat}"] = float(per[c, j])
            out[f"test/{split}/surface_empty{suffix}"] = float(res["empty_per_category"].sum())
            metric.reset()
    return out
