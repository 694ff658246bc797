"""WGAN-GP critic of the 3DCascade-GAN (thesis fig. 3.2).

concat(nearest-upsampled partial, shape) -> N x [Conv3d k=4 s=2 p=1, LeakyReLU(0.2)] (the last
conv linear), no normalisation (WGAN-GP), self-attention after the layer whose output is
``attention_res``^3, output = per-sample mean of the last feature map (optionally after the
thesis's sigmoid).
"""
from __future__ import annotations

from collections.abc import Sequence

import torch
import torch.nn as nn
import torch.nn.functional as F

from lit3d.completion.attention import SelfAttention3d


class Critic(nn.Module):
    """WGAN-GP critic on (partial input, shape) pairs (thesis fig. 3.2).

    forward(partial (B, 1, r, r, r) in {0, 1}, shape (B, 1, R, R, R) probabilities) -> (B,)
    The partial grid is nearest-upsampled to R^3 and concatenated (2 channels). Each of the
    ``len(channels)`` layers is Conv3d k=4 s=2 p=1 followed by LeakyReLU(0.2), except the last
    (linear); self-attention follows the layer whose output side equals ``attention_res``.
    Output = per-sample mean of the last map, after a sigmoid when ``sigmoid=True`` (thesis).
    """

    def __init__(
        self,
        in_res: int,
        channels: Sequence[int],
        attention_res: int | None = None,
        use_attention: bool = True,
        sigmoid: bool = False,
    ):
        super().__init__()
        channels = list(channels)
        if use_attention and attention_res is None:
            raise ValueError("critic: use_attention needs attention_res (the layer output side it follows)")
        if in_res % 2 ** len(channels):
            raise ValueError(f"critic: in_res={in_res} cannot be halved {len(channels)} times")
        self.in_res, self.sigmoid = in_res, sigmoid
        self.layers = nn.ModuleList()
        self.attn_after: int | None = None
        self.attn = None
        cin, res = 2, in_res
        for i, c in enumerate(channels):
            res //= 2
            last = i == len(channels) - 1
            self.layers.append(nn.Sequential(nn.Conv3d(cin, c, 4, stride=2, padding=1),
                                             *( [] if last else [nn.LeakyReLU(0.2, inplace=True)] )))
            if use_attention and res == attention_res and not last and self.attn is None:
                self.attn_after, self.attn = i, SelfAttention3d(c)
            cin = c
        if use_attention and self.attn is None:
            raise ValueError(f"critic: no layer output is {attention_res}^3 (in_res={in_res}, {len(channels)} layers)")

    def forward(self, partial: torch.Tensor, shape: torch.Tensor) -> torch.Tensor:
        p = partial.to(shape.dtype)
        if p.shape[-3:] != shape.shape[-3:]:
            p = F.interpolate(p, size=shape.shape[-3:], mode="nearest")
        h = torch.cat([p, shape], 1)
        for i, layer in enumerate(self.layers):
            h = layer(h)
            if i == self.attn_after:
                h = self.attn(h)
        if self.sigmoid:
            h = torch.sigmoid(h)
        return h.flatten(1).mean(1)
