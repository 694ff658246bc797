"""Colour to grey conversion for rendered views."""
from __future__ import annotations

import torch
from kornia.color import rgb_to_grayscale


def to_grey(rgb: torch.Tensor) -> torch.Tensor:
    """ITU-R BT.601 luma ``(B, 1, H, W)`` of ``(B, 3, H, W)`` images (grey ``(B, 1, H, W)`` passes through).

    ``kornia.color.rgb_to_grayscale`` (weights 0.299, 0.587, 0.114; same dtype as the input).
    """
    if rgb.shape[1] == 1:
        return rgb
    return rgb_to_grayscale(rgb)
