"""SAGAN-style 3D self-attention (thesis section 3.2.2, eqs. 3.2-3.4).

For a feature map ``x`` of shape ``(B, C, D, H, W)`` with ``N = D*H*W`` positions:

    f, g: 1x1x1 convs C -> C // reduction   (keys / queries)
    h:    1x1x1 conv  C -> C // 2           (values)
    v:    1x1x1 conv  C // 2 -> C           (output projection)
    beta[j, i] = softmax_i( f(x_i)^T g(x_j) )          (no 1/sqrt(d) scaling, as in SAGAN)
    o_j = v( sum_i beta[j, i] h(x_i) )
    y = gamma * o + x,  gamma a learned scalar initialised to 0 (the layer starts as the identity)

The attention matrix is ``N x N`` per sample (16^3 positions -> 4096^2 floats = 64 MB in
fp32 for the explicit form); :func:`torch.nn.functional.scaled_dot_product_attention` computes the
same result without materialising it when a fused kernel is available.

Note for WGAN-GP: the fused CUDA kernels (flash / memory-efficient) have no double backward.
:func:`lit3d.completion.losses.gradient_penalty` therefore runs the critic under the MATH backend.
"""
from __future__ import annotations

import torch
import torch.nn as nn
import torch.nn.functional as F


class SelfAttention3d(nn.Module):
    """3D self-attention ``(B, C, D, H, W) -> (B, C, D, H, W)`` (same dtype as the input).

    Args:
        channels: ``C``.
        reduction: key/query channels are ``max(C // reduction, 1)``.
        use_sdpa: compute with ``scaled_dot_product_attention`` (default) or the explicit
            softmax form (same result; kept for tests and for inspecting the attention map).
    """

    def __init__(self, channels: int, reduction: int = 8, use_sdpa: bool = True):
        super().__init__()
        qk = max(channels // reduction, 1)
        hv = max(channels // 2, 1)
        self.f = nn.Conv3d(channels, qk, 1)
        self.g = nn.Conv3d(channels, qk, 1)
        self.h = nn.Conv3d(channels, hv, 1)
        self.v = nn.Conv3d(hv, channels, 1)
        self.gamma = nn.Parameter(torch.zeros(1))
        self.use_sdpa = use_sdpa

    def _qkv(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Queries g(x_j), keys f(x_i), values h(x_i) as ``(B, 1, N, c)`` (one head)."""
        q = self.g(x).flatten(2).transpose(1, 2).unsqueeze(1)
        k = self.f(x).flatten(2).transpose(1, 2).unsqueeze(1)
        v = self.h(x).flatten(2).transpose(1, 2).unsqueeze(1)
        return q, k, v

    def attention_map(self, x: torch.Tensor) -> torch.Tensor:
        """``beta``: ``(B, N, N)``, row ``j`` = weights over positions ``i`` (rows sum to 1)."""
        q, k, _ = self._qkv(x)
        return torch.softmax(q.squeeze(1) @ k.squeeze(1).transpose(1, 2), dim=-1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        b, c, d, hh, w = x.shape
        q, k, v = self._qkv(x)
        if self.use_sdpa:
            o = F.scaled_dot_product_attention(q, k, v, scale=1.0)
        else:
            beta = torch.softmax(q @ k.transpose(-1, -2), dim=-1)
            o = beta @ v
        o = o.squeeze(1).transpose(1, 2).reshape(b, -1, d, hh, w)
        return self.gamma * self.v(o) + x
