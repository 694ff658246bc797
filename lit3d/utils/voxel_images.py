"""Pictures of voxel grids without a renderer: depth-shaded projections.

A grid is looked at along one axis; each pixel shows how near the first
occupied voxel is (near = bright), so shapes read as 3D in a flat PNG.
"""
from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F


def depth_shaded(volume: torch.Tensor, threshold: float = 0.5, axis: int = 0) -> np.ndarray:
    """(D, H, W) occupancy or probabilities -> (H', W') uint8 image.

    Background is 0; occupied columns are shaded 255 (nearest) .. 70 (farthest).
    """
    occ = (volume.detach().float().cpu() >= threshold).movedim(axis, 0)
    d = occ.shape[0]
    hit = occ.any(0)
    first = torch.argmax(occ.to(torch.uint8), dim=0).float()
    shade = 255.0 - 185.0 * first / max(d - 1, 1)
    return torch.where(hit, shade, torch.zeros_like(shade)).to(torch.uint8).numpy()


def to_resolution(volume: torch.Tensor, size: int) -> torch.Tensor:
    """(D, H, W) grid -> (size, size, size) by nearest up/down-sampling."""
    v = volume.detach().float()[None, None]
    if v.shape[-1] == size:
        return v[0, 0]
    if v.shape[-1] > size:
        return F.adaptive_max_pool3d(v, size)[0, 0]
    return F.interpolate(v, size=(size,) * 3, mode="nearest")[0, 0]


def panel(volumes: list[torch.Tensor], threshold: float = 0.5, size: int | None = None, gap: int = 2) -> np.ndarray:
    """Side-by-side depth-shaded views of several (D, H, W) grids at one resolution -> uint8 (H, W)."""
    size = size or max(int(v.shape[-1]) for v in volumes)
    tiles = [depth_shaded(to_resolution(v, size), threshold) for v in volumes]
    sep = np.full((size, gap), 40, dtype=np.uint8)
    row: list[np.ndarray] = []
    for t in tiles:
        row.extend([t, sep])
    return np.concatenate(row[:-1], axis=1)
