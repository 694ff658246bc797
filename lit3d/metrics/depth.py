"""Depth-image metrics of predicted canonical forms: masked depth MSE and mask IoU.

Functional forms give one value per sample; the :class:`~torchmetrics.Metric` twins average
those per-sample values over everything they were updated with (sum and count states reduced
by ``"sum"``, so the mean is the same under DDP as on one process).

Inputs are ``(B, 1, H, W)`` (or ``(B, H, W)``) float tensors: depths in [0, 1] (0 =
background), masks in [0, 1] (predicted: probabilities, binarised at ``threshold``; target:
{0, 1}, binarised at 0.5).
"""
from __future__ import annotations

import torch
from torchmetrics import Metric


def composite_depth(depth: torch.Tensor, mask: torch.Tensor, threshold: float = 0.5) -> torch.Tensor:
    """Depth with background set to 0 where ``mask < threshold``: the depth image a prediction
    stands for. Same shape and dtype as ``depth``."""
    return torch.where(mask >= threshold, depth, torch.zeros_like(depth))


def per_sample_depth_mse(depth_hat: torch.Tensor, mask_hat: torch.Tensor, depth: torch.Tensor,
                         mask: torch.Tensor, threshold: float = 0.5) -> torch.Tensor:
    """Masked depth MSE per sample ``(B,)`` float32: squared error of the composited depths over the
    union of the predicted (binarised) and true masks; background counts as depth 0, so a
    missing or extra limb costs its whole depth. Empty union -> 0."""
    pm = (mask_hat >= threshold).float()
    tm = (mask >= 0.5).float()
    union = torch.maximum(pm, tm)
    err = (composite_depth(depth_hat, mask_hat, threshold).float() - depth.float() * tm) ** 2 * union
    n = union.flatten(1).sum(1)
    return err.flatten(1).sum(1) / n.clamp_min(1)


def per_sample_mask_iou(mask_hat: torch.Tensor, mask: torch.Tensor, threshold: float = 0.5) -> torch.Tensor:
    """IoU of the binarised masks per sample ``(B,)`` float32; both empty -> 1."""
    p = (mask_hat >= threshold).flatten(1)
    t = (mask >= 0.5).flatten(1)
    inter = (p & t).sum(1).float()
    union = (p | t).sum(1).float()
    return torch.where(union > 0, inter / union.clamp_min(1), torch.ones_like(union))


class _PerSampleMean(Metric):
    """Mean of per-sample values: ``total`` (sum) and ``count`` states, both reduced by sum."""

    full_state_update = False
    higher_is_better: bool | None = None

    def __init__(self, threshold: float = 0.5, **kwargs):
        super().__init__(**kwargs)
        self.threshold = float(threshold)
        self.add_state("total", torch.tensor(0.0), dist_reduce_fx="sum")
        self.add_state("count", torch.tensor(0.0), dist_reduce_fx="sum")

    def _add(self, values: torch.Tensor) -> None:
        self.total += values.sum()
        self.count += values.numel()

    def compute(self) -> torch.Tensor:
        """Scalar float32: mean per-sample value (0 before any update)."""
        return self.total / self.count.clamp_min(1)


class MaskedDepthMSE(_PerSampleMean):
    """Mean of :func:`per_sample_depth_mse` over the samples seen; lower is better."""

    higher_is_better = False

    def update(self, depth_hat: torch.Tensor, mask_hat: torch.Tensor, depth: torch.Tensor,
               mask: torch.Tensor) -> None:
        self._add(per_sample_depth_mse(depth_hat, mask_hat, depth, mask, self.threshold))


class MaskIoU(_PerSampleMean):
    """Mean of :func:`per_sample_mask_iou` over the samples seen; higher is better."""

    higher_is_better = True

    def update(self, mask_hat: torch.Tensor, mask: torch.Tensor) -> None:
        self._add(per_sample_mask_iou(mask_hat, mask, self.threshold))
