"""Losses of the canonical-form task (thesis eq. 5.8-5.10); its image metrics are in
:mod:`lit3d.metrics.depth`.

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
