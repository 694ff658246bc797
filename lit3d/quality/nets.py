"""The thesis's quality MLP (ch. 4, Figure 4.4) and a batched twin for feature selection.

    x (B, F) float32 features of a mesh pair
      -> BatchNorm1d(F)             (switch: ``batch_norm``; table 4.6 ablation)
      -> Dropout(p)
      -> Linear(F, H) -> ReLU
      -> ``blocks`` x residual block [Linear(H, H) -> ReLU -> Linear(H, H)] + skip -> ReLU
      -> Linear(H, 1) -> sigmoid
    -> (B,) float32 in (0, 1): predicted distortion (0 = like the reference).

:class:`BatchedQualityMLP` holds ``M`` independent copies of the same network as
stacked parameters, so the many small models Sequential Forward Search trains
(one per candidate feature set) train together in one loop. With ``M = 1`` and
copied weights it computes exactly what :class:`QualityMLP` computes.
"""
from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import nn


class ResidualBlock(nn.Module):
    """``relu(x + fc2(relu(fc1(x))))`` on (B, H)."""

    def __init__(self, width: int):
        super().__init__()
        self.fc1 = nn.Linear(width, width)
        self.fc2 = nn.Linear(width, width)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return F.relu(x + self.fc2(F.relu(self.fc1(x))))


class QualityMLP(nn.Module):
    """(B, in_features) float32 -> (B,) float32 in (0, 1)."""

    def __init__(self, in_features: int, hidden: int, blocks: int, dropout: float = 0.1,
                 batch_norm: bool = True):
        super().__init__()
        if in_features < 1:
            raise ValueError(f"QualityMLP needs at least one input feature, got {in_features}")
        self.in_features = in_features
        self.norm = nn.BatchNorm1d(in_features) if batch_norm else nn.Identity()
        self.drop = nn.Dropout(dropout)
        self.fc_in = nn.Linear(in_features, hidden)
        self.blocks = nn.ModuleList(ResidualBlock(hidden) for _ in range(blocks))
        self.fc_out = nn.Linear(hidden, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        h = F.relu(self.fc_in(self.drop(self.norm(x))))
        for block in self.blocks:
            h = block(h)
        return torch.sigmoid(self.fc_out(h)).squeeze(-1)


def _linear_init(m: int, fan_in: int, fan_out: int, generator: torch.Generator) -> tuple[torch.Tensor, torch.Tensor]:
    """nn.Linear's default init (kaiming-uniform a=sqrt(5) == U(-1/sqrt(fan_in), 1/sqrt(fan_in)))."""
    bound = 1.0 / math.sqrt(fan_in)
    w = (torch.rand(m, fan_in, fan_out, generator=generator) * 2 - 1) * bound
    b = (torch.rand(m, 1, fan_out, generator=generator) * 2 - 1) * bound
    return w, b


class BatchedQualityMLP(nn.Module):
    """``M`` independent :class:`QualityMLP`s with the same input width.

    forward: (M, B, in_features) float32 -> (M, B) float32 in (0, 1).
    Batch norm uses per-model batch statistics in training and running statistics
    (momentum 0.1, unbiased running variance, like ``nn.BatchNorm1d``) in eval.
    """

    def __init__(self, n_models: int, in_features: int, hidden: int, blocks: int,
                 dropout: float = 0.1, batch_norm: bool = True, seed: int = 0, eps: float = 1e-5,
                 momentum: float = 0.1):
        super().__init__()
        g = torch.Generator().manual_seed(seed)
        self.n_models, self.in_features, self.batch_norm = n_models, in_features, batch_norm
        self.dropout, self.eps, self.momentum = dropout, eps, momentum
        if batch_norm:
            self.bn_weight = nn.Parameter(torch.ones(n_models, 1, in_features))
            self.bn_bias = nn.Parameter(torch.zeros(n_models, 1, in_features))
            self.register_buffer("running_mean", torch.zeros(n_models, 1, in_features))
            self.register_buffer("running_var", torch.ones(n_models, 1, in_features))
        w, b = _linear_init(n_models, in_features, hidden, g)
        self.w_in, self.b_in = nn.Parameter(w), nn.Parameter(b)
        self.w_blocks = nn.ParameterList()
        self.b_blocks = nn.ParameterList()
        for _ in range(blocks * 2):
            w, b = _linear_init(n_models, hidden, hidden, g)
            self.w_blocks.append(nn.Parameter(w))
            self.b_blocks.append(nn.Parameter(b))
        w, b = _linear_init(n_models, hidden, 1, g)
        self.w_out, self.b_out = nn.Parameter(w), nn.Parameter(b)

    def _norm(self, x: torch.Tensor) -> torch.Tensor:
        if not self.batch_norm:
            return x
        if self.training:
            mean = x.mean(1, keepdim=True)
            var = x.var(1, unbiased=False, keepdim=True)
            with torch.no_grad():
                n = x.shape[1]
                unbiased = var * (n / max(n - 1, 1))
                self.running_mean.lerp_(mean, self.momentum)
                self.running_var.lerp_(unbiased, self.momentum)
        else:
            mean, var = self.running_mean, self.running_var
        return (x - mean) / torch.sqrt(var + self.eps) * self.bn_weight + self.bn_bias

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        x = F.dropout(self._norm(x), self.dropout, self.training)
        h = F.relu(torch.baddbmm(self.b_in, x, self.w_in))
        for i in range(0, len(self.w_blocks), 2):
            r = F.relu(torch.baddbmm(self.b_blocks[i], h, self.w_blocks[i]))
            h = F.relu(h + torch.baddbmm(self.b_blocks[i + 1], r, self.w_blocks[i + 1]))
        return torch.sigmoid(torch.baddbmm(self.b_out, h, self.w_out)).squeeze(-1)

    def to_single(self, index: int) -> QualityMLP:
        """Copy model ``index`` into a plain :class:`QualityMLP` (same outputs)."""
        blocks = len(self.w_blocks) // 2
        net = QualityMLP(self.in_features, self.w_in.shape[-1], blocks, self.dropout, self.batch_norm)
        with torch.no_grad():
            if self.batch_norm:
                net.norm.weight.copy_(self.bn_weight[index, 0])
                net.norm.bias.copy_(self.bn_bias[index, 0])
                net.norm.running_mean.copy_(self.running_mean[index, 0])
                net.norm.running_var.copy_(self.running_var[index, 0])
            net.fc_in.weight.copy_(self.w_in[index].T)
            net.fc_in.bias.copy_(self.b_in[index, 0])
            for k, block in enumerate(net.blocks):
                block.fc1.weight.copy_(self.w_blocks[2 * k][index].T)
                block.fc1.bias.copy_(self.b_blocks[2 * k][index, 0])
                block.fc2.weight.copy_(self.w_blocks[2 * k + 1][index].T)
                block.fc2.bias.copy_(self.b_blocks[2 * k + 1][index, 0])
            net.fc_out.weight.copy_(self.w_out[index].T)
            net.fc_out.bias.copy_(self.b_out[index, 0])
        return net


def count_parameters(net: nn.Module) -> int:
    return sum(p.numel() for p in net.parameters())
