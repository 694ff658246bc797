"""Losses of the canonical-form task (thesis eq. 5.8-5.10) and of the warp head (flow, visibility,
smoothness); its image metrics are in :mod:`lit3d.metrics.depth`.

All inputs are ``(B, 1, H, W)`` float tensors: depths in [0, 1] (0 = background),
masks in [0, 1] (predicted: probabilities; target: {0, 1}). Computed in fp32.
"""
from __future__ import annotations

import torch


def masked_depth_loss(depth_hat: torch.Tensor, mask_hat: torch.Tensor, depth: torch.Tensor,
                      mask: torch.Tensor) -> torch.Tensor:
    """L_depth = mean(m_hat * m * (d_hat - d)^2) over all pixels (thesis eq. 5.8). Scalar."""
    return (mask_hat.float() * mask.float() * (depth_hat.float() - depth.float()) ** 2).mean()


def mask_loss(mask_hat: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """L_mask = mean((m_hat - m)^2) (thesis eq. 5.9). Scalar."""
    return ((mask_hat.float() - mask.float()) ** 2).mean()


def canonical_loss(depth_hat, mask_hat, depth, mask, alpha: float, beta: float, mask_kind: str = "mse",
                   mask_logits: torch.Tensor | None = None) -> dict[str, torch.Tensor]:
    """``{"loss": alpha L_depth + beta L_mask, "depth": L_depth, "mask": L_mask}``.

    ``mask_kind``: "mse" (thesis eq. 5.9, on probabilities) or "bce" (from ``mask_logits``)."""
    ld = masked_depth_loss(depth_hat, mask_hat, depth, mask)
    if mask_kind == "mse":
        lm = mask_loss(mask_hat, mask)
    elif mask_kind == "bce":
        if mask_logits is None:
            raise ValueError("mask_kind='bce' needs mask_logits")
        lm = mask_bce_loss(mask_logits, mask)
    else:
        raise ValueError(f"mask loss must be 'mse' or 'bce', got '{mask_kind}'")
    return {"loss": alpha * ld + beta * lm, "depth": ld, "mask": lm}


def mask_bce_loss(mask_logits: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """Binary cross-entropy of the mask, from logits (fp32). An option beside the thesis's MSE:
    at small scale the MSE on sigmoid probabilities collapses to an all-background mask."""
    return torch.nn.functional.binary_cross_entropy_with_logits(mask_logits.float(), mask.float())


def _per_item(weight: torch.Tensor, has_flow: torch.Tensor) -> torch.Tensor:
    """``weight`` ``(B, 1, H, W)`` zeroed for the items without flow targets (``has_flow`` ``(B,)`` bool)."""
    return weight.float() * has_flow.float().view(-1, 1, 1, 1).to(weight.device)


def flow_loss(flow: torch.Tensor, target: torch.Tensor, vis: torch.Tensor, has_flow: torch.Tensor) -> torch.Tensor:
    """Mean end-point distance (normalised grid units, the net's) between the predicted flow
    ``(B, 2, H, W)`` and the target ``(B, 2, H, W)`` (same units) over the pixels ``vis``
    ``(B, 1, H, W)`` of the items with targets; 0 when there are none. Scalar, fp32."""
    w = _per_item(vis, has_flow)
    epe = torch.sqrt(((flow.float() - target.float()) ** 2).sum(1, keepdim=True) + 1e-8)
    return (w * epe).sum() / w.sum().clamp_min(1.0)


def visibility_loss(vis_logits: torch.Tensor, vis: torch.Tensor, where: torch.Tensor,
                    has_flow: torch.Tensor) -> torch.Tensor:
    """Binary cross-entropy of the visibility logits ``(B, 1, H, W)`` against ``vis`` on the pixels
    ``where`` ``(B, 1, H, W)`` (the canonical foreground) of the items with targets; 0 when there
    are none. Scalar, fp32."""
    w = _per_item(where, has_flow)
    bce = torch.nn.functional.binary_cross_entropy_with_logits(vis_logits.float(), vis.float(), reduction="none")
    return (w * bce).sum() / w.sum().clamp_min(1.0)


def flow_smoothness(flow: torch.Tensor) -> torch.Tensor:
    """Mean absolute difference of neighbouring flow vectors ``(B, 2, H, W)`` (first-order total variation;
    any ``(B, C, H, W)`` map). Scalar."""
    f = flow.float()
    return (f[..., 1:, :] - f[..., :-1, :]).abs().mean() + (f[..., :, 1:] - f[..., :, :-1]).abs().mean()
