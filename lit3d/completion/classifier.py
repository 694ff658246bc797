"""Auxiliary category classifier of the 3DCascade-GAN (thesis fig. 3.3)."""
from __future__ import annotations

from collections.abc import Sequence

import torch
import torch.nn as nn
import torch.nn.functional as F

from lit3d.completion.layers import same_conv


class ShapeClassifier(nn.Module):
    """Auxiliary category classifier (thesis fig. 3.3).

    forward(shape (B, 1, R, R, R) probabilities) -> (B, n_classes) logits. The shape is
    max-pooled to ``in_res``^3, then [Conv3d k=4 s=1 'same', LeakyReLU(0.2), MaxPool 2] while the
    grid side is above 4 and channels remain, then Linear.
    """

    def __init__(self, in_res: int, channels: Sequence[int], n_classes: int):
        super().__init__()
        self.in_res = in_res
        layers, cin, res = [], 1, in_res
        for c in channels:
            if res <= 4 or res % 2:
                break
            layers += [same_conv(cin, c), nn.LeakyReLU(0.2, inplace=True), nn.MaxPool3d(2)]
            cin, res = c, res // 2
        self.features = nn.Sequential(*layers)
        self.head = nn.Linear(cin * res**3, n_classes)

    def forward(self, shape: torch.Tensor) -> torch.Tensor:
        if shape.shape[-1] != self.in_res:
            if shape.shape[-1] % self.in_res:
                raise ValueError(f"classifier: grid {shape.shape[-1]} is not a multiple of in_res={self.in_res}")
            shape = F.max_pool3d(shape, shape.shape[-1] // self.in_res)
        return self.head(self.features(shape).flatten(1))
