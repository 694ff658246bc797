"""Per-sample test IoUs and the paired comparisons of results.md: the model against the
input-as-prediction and silhouette-extrusion baselines on the same samples, with bootstrap
95% intervals (:mod:`lit3d.metrics.bootstrap`), per split and category.

Also the silhouette-extrusion baseline itself: every voxel behind a visible input voxel along
the depth camera's axis is filled (the one-view visual hull of the partial grid).
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


def extrude_silhouette(partial: torch.Tensor, size: int, axis: int = -1) -> torch.Tensor:
    """The one-view visual hull ``(B, 1, size, size, size) float32`` of a partial grid.

    Args:
        partial: ``(B, 1, r, r, r)`` {0, 1}; along ``axis`` index 0 is nearest the depth camera
            (:mod:`datamodules.synth.depth_voxels`; the 3D-RecGAN++ grids share the convention).
        size: output side (nearest upsampling, as the input-as-prediction baseline).
    """
    filled = (partial > 0.5).cummax(dim=axis).values.float()
    return F.interpolate(filled, size=(size,) * 3, mode="nearest")


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
        got = self.samples.compute()
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
