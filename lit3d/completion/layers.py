"""Conv building blocks shared by the 3DCascade-GAN generator and classifier."""
from __future__ import annotations

import torch.nn as nn


def same_conv(cin: int, cout: int, k: int = 4) -> nn.Sequential:
    """Conv3d k, stride 1: (B, cin, D, H, W) -> (B, cout, D, H, W) (asymmetric zero padding for
    even k, like TensorFlow's 'same')."""
    lo = (k - 1) // 2
    hi = k - 1 - lo
    return nn.Sequential(nn.ConstantPad3d((lo, hi, lo, hi, lo, hi), 0.0), nn.Conv3d(cin, cout, k))


def up_conv(cin: int, cout: int) -> nn.ConvTranspose3d:
    """ConvTranspose3d k=4 s=2 p=1: (B, cin, D, H, W) -> (B, cout, 2D, 2H, 2W)."""
    return nn.ConvTranspose3d(cin, cout, 4, stride=2, padding=1)
