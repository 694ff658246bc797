"""What every canonical-form net returns, and the plain 1x1 head that draws it (the thesis's redraw).

Tensors (B = batch, H x W = image size): depth ``(B, 1, H, W)`` in [0, 1], mask probability and
mask logits ``(B, 1, H, W)``; the warp head (:mod:`lit3d.canonical.warp`) also returns its flow
``(B, 2, H, W)`` (normalised grid units: 2 = the image width) and visibility logits ``(B, 1, H, W)`` at
the canonical pixels.
"""
from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn as nn


@dataclass
class CanonicalOutput:
    """Predicted canonical depth ``(B,1,H,W)`` in [0,1], mask probability and mask logits ``(B,1,H,W)``;
    ``latent``: the MSFE's fused latent ``(B, fuser_out)`` (None without an MSFE, and for the U-Net);
    ``flow`` ``(B,2,H,W)`` and ``vis_logits`` ``(B,1,H,W)``: the warp head's (None for the others)."""

    depth: torch.Tensor
    mask: torch.Tensor
    mask_logits: torch.Tensor
    latent: torch.Tensor | None = None
    flow: torch.Tensor | None = None
    vis_logits: torch.Tensor | None = None


class OutputHead(nn.Module):
    """1x1 conv -> depth (sigmoid) and mask logits."""

    def __init__(self, cin: int):
        super().__init__()
        self.conv = nn.Conv2d(cin, 2, 1)

    def forward(self, h: torch.Tensor) -> CanonicalOutput:
        o = self.conv(h)
        logits = o[:, 1:2]
        return CanonicalOutput(depth=torch.sigmoid(o[:, 0:1]), mask=torch.sigmoid(logits), mask_logits=logits)
