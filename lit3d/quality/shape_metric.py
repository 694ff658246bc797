"""Per-shape correlation as a torchmetrics :class:`~torchmetrics.Metric`, right under DDP.

The thesis reports Pearson and Spearman *per reference shape*, then their mean over shapes, so
the metric keeps every (prediction, target, shape id) it sees as "cat" states: torchmetrics
gathers them from all ranks before :meth:`PerShapeCorrelation.compute`, which then applies
:func:`lit3d.quality.correlation.shape_corr_metrics` (SciPy; constant input -> 0.0) to the whole
split. Every rank therefore computes the same numbers from the same rows.
"""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch
from torchmetrics import Metric
from torchmetrics.utilities import dim_zero_cat

from lit3d.quality.correlation import shape_corr_metrics


class PerShapeCorrelation(Metric):
    """update(pred (B,) float, target (B,) float, shape_id (B,) int64 index into ``shape_names``);
    compute() -> ``{"pearson/<shape>": r, "pearson": mean over shapes, "spearman/...": ...}`` (floats).
    """

    full_state_update = False

    def __init__(self, shape_names: Sequence[str] = ()):
        super().__init__()
        self.shape_names = list(shape_names)
        self.add_state("pred", default=[], dist_reduce_fx="cat")
        self.add_state("target", default=[], dist_reduce_fx="cat")
        self.add_state("shape_id", default=[], dist_reduce_fx="cat")

    def update(self, pred: torch.Tensor, target: torch.Tensor, shape_id: torch.Tensor) -> None:
        self.pred.append(pred.detach().double().flatten())
        self.target.append(target.detach().double().flatten())
        self.shape_id.append(shape_id.detach().long().flatten())

    def compute(self) -> dict[str, float]:
        if isinstance(self.pred, list) and not self.pred:  # after a DDP sync the states are tensors
            return {}
        ids = dim_zero_cat(self.shape_id).cpu().numpy()
        if ids.size and int(ids.max()) >= len(self.shape_names):
            raise IndexError(f"shape id {int(ids.max())} has no name (the metric knows {len(self.shape_names)} shapes)")
        shapes = np.asarray(self.shape_names, dtype=str)[ids]
        pred = dim_zero_cat(self.pred).cpu().numpy()
        target = dim_zero_cat(self.target).cpu().numpy()
        return {k.lstrip("/"): v for k, v in shape_corr_metrics("", pred, target, shapes).items()}
