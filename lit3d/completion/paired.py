"""Per-sample test IoUs and the paired comparisons of results.md: the model against the
input-as-prediction and silhouette-extrusion baselines on the same samples, with bootstrap
95% intervals (:mod:`lit3d.metrics.bootstrap`), per split and category.

Also the silhouette-extrusion baseline itself (:func:`extrude_silhouette`).
"""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch
import torch.nn.functional as F

from lit3d.metrics.bootstrap import mean_ci, paired_difference_ci
from lit3d.metrics.gathered import GatheredTensors
from lit3d.metrics.voxel import iou_at_thresholds

BASELINES = ("input", "extrusion")


def extrude_silhouette(partial: torch.Tensor, size: int) -> torch.Tensor:
    """Silhouette extrusion ``(B, 1, size, size, size) float32``: the partial grid extruded away
    from the camera, behind each visible voxel of a column, down to the deepest visible voxel of
    the sample (not to the grid's far side, which would fill empty space behind every shape).

    Args:
        partial: ``(B, 1, r, r, r)`` {0, 1}; along the last axis index 0 is nearest the depth
            camera (:mod:`datamodules.completion.depth_voxels`).
        size: output side (nearest upsampling, as the input-as-prediction baseline).
    """
    occ = partial > 0.5
    behind = occ.cummax(dim=-1).values  # at or behind the first visible voxel of the column
    k = torch.arange(occ.shape[-1], device=occ.device)
    deepest = torch.where(occ, k, torch.full_like(k, -1)).flatten(1).amax(1)  # (B,) -1: empty
    filled = behind & (k <= deepest.view(-1, 1, 1, 1, 1))
    return F.interpolate(filled.float(), size=(size,) * 3, mode="nearest")


class PairedSamples(torch.nn.Module):
    """Per-sample IoU of the model and the baselines, gathered over the test epoch (DDP-safe)."""

    def __init__(self):
        super().__init__()
        self.samples = GatheredTensors(("split", "category", "model", *BASELINES))

    def update(self, split: int, category: torch.Tensor, preds: dict[str, torch.Tensor], target: torch.Tensor,
               thresholds: dict[str, float]) -> None:
        """``preds[src]``: ``(B, 1, R, R, R)`` probabilities; ``category``: ``(B,)`` indices."""
        ious = {src: iou_at_thresholds(preds[src], target, torch.tensor([thresholds[src]]))[:, 0].float()
                for src in ("model", *BASELINES)}
        n = target.shape[0]
        self.samples.update(split=torch.full((n,), split, dtype=torch.long), category=category.long().cpu(),
                            **{k: v.cpu() for k, v in ious.items()})

    def summary(self, splits: Sequence[str], categories: Sequence[str]) -> dict[str, float]:
        """``test/<split>/paired/...`` keys: ``n``, ``model``/``<baseline>`` means, the model's mean
        with its interval (``model_lo``/``model_hi``), and per baseline ``margin_<b>`` with
        ``_lo``/``_hi``, for all samples of the split and per category (``.../<category>``)."""
        got = {k: v.cpu() for k, v in self.samples.compute().items()}  # the states live on the task's device
        out: dict[str, float] = {}
        if not got:
            return out
        # one canonical order (by value), so the bootstrap draws do not depend on how the samples
        # were spread over processes
        keys = [got[k].double().numpy() for k in ("extrusion", "input", "model", "category", "split")]
        order = torch.from_numpy(np.lexsort(keys))
        got = {k: v[order] for k, v in got.items()}
        for s, split in enumerate(splits):
            rows = got["split"] == s
            if not bool(rows.any()):
                continue
            groups = [("", rows)] + [(f"/{c}", rows & (got["category"] == k)) for k, c in enumerate(categories)]
            for suffix, m in groups:
                if not bool(m.any()):
                    continue
                model = got["model"][m].double().numpy()
                base = f"test/{split}/paired"
                out[f"{base}/n{suffix}"] = float(m.sum())
                mean, lo, hi = mean_ci(model)
                out.update({f"{base}/model{suffix}": mean, f"{base}/model_lo{suffix}": lo,
                            f"{base}/model_hi{suffix}": hi})
                for b in BASELINES:
                    other = got[b][m].double().numpy()
                    d, dlo, dhi = paired_difference_ci(model, other)
                    out.update({f"{base}/{b}{suffix}": float(other.mean()), f"{base}/margin_{b}{suffix}": d,
                                f"{base}/margin_{b}_lo{suffix}": dlo, f"{base}/margin_{b}_hi{suffix}": dhi})
        return out

    def reset(self) -> None:
        self.samples.reset()
