"""Nearest neighbours between batched point clouds (torch tensors, any device), for the surface
metrics of :mod:`lit3d.metrics.clouds`.

Clouds are ``x (B, N, 3)`` and ``y (B, M, 3)``, optionally ragged: ``x_lengths (B,)`` says how many of
each row's points are real (the rest is padding, ignored), as in PyTorch3D. Two backends find the
neighbour indices:

- ``"cdist"``: exhaustive :func:`torch.cdist` on the tensors' device, ``max_pairs`` distances at a time
  (rows of ``x`` in chunks), so memory stays bounded on any cloud size; the GPU path;
- ``"kdtree"``: SciPy's ``cKDTree``, one tree per batch row, on the CPU (``O(N log M)``: what a CPU
  wants for the 30 000-point samples of the completion tables);
- ``"auto"`` (default): ``"kdtree"`` for CPU tensors, ``"cdist"`` otherwise.

Either way the returned distances are computed afterwards as ``||x_i - y_nn(i)||`` in the inputs' dtype,
so they are exact (not the matrix-product form of ``cdist``), the same for both backends, and
differentiable with respect to ``x`` and ``y`` (a Chamfer loss).
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
import torch

BACKENDS = ("auto", "cdist", "kdtree")
MAX_PAIRS = 1 << 24  # pairwise distances held at once by the cdist backend (64 MiB in float32)


class Neighbours(NamedTuple):
    """Each ``x`` point's nearest ``y`` point: ``distance (B, N)`` (0 on padding) and ``index (B, N)`` int64
    into ``y``'s second axis (0 on padding)."""

    distance: torch.Tensor
    index: torch.Tensor


def cloud_lengths(points: torch.Tensor, lengths: torch.Tensor | None, name: str = "points") -> torch.Tensor:
    """Check ``points (B, N, 3)`` and return the real point count of each row, ``(B,)`` int64 on the
    points' device (``N`` everywhere when ``lengths`` is None). Raises ValueError on another shape or a
    length outside ``[1, N]`` (a cloud without points has no nearest neighbour)."""
    if points.dim() != 3 or points.shape[-1] != 3:
        raise ValueError(f"{name}: expected a (B, N, 3) point cloud tensor, got shape {tuple(points.shape)}")
    b, n = points.shape[:2]
    if lengths is None:
        if n == 0:
            raise ValueError(f"{name}: a cloud of 0 points has no nearest neighbour")
        return torch.full((b,), n, dtype=torch.int64, device=points.device)
    lengths = torch.as_tensor(lengths, device=points.device).long().reshape(-1)
    if lengths.numel() != b or bool(((lengths < 1) | (lengths > n)).any()):
        raise ValueError(f"{name}_lengths: expected {b} counts in [1, {n}], got {lengths.tolist()}")
    return lengths


def valid_mask(lengths: torch.Tensor, n: int) -> torch.Tensor:
    """``(B, n)`` bool: True where a point index is below its row's length."""
    return torch.arange(n, device=lengths.device)[None, :] < lengths[:, None]


def _index_cdist(x: torch.Tensor, y: torch.Tensor, y_lengths: torch.Tensor, max_pairs: int) -> torch.Tensor:
    b, n, m = x.shape[0], x.shape[1], y.shape[1]
    rows = max(1, int(max_pairs) // max(1, b * m))
    pad = ~valid_mask(y_lengths, m)[:, None, :]  # (B, 1, M)
    out = torch.empty((b, n), dtype=torch.int64, device=x.device)
    with torch.no_grad():
        for start in range(0, n, rows):
            d = torch.cdist(x[:, start:start + rows], y)  # (B, c, M)
            out[:, start:start + rows] = d.masked_fill(pad, float("inf")).argmin(-1)
    return out


def _index_kdtree(x: torch.Tensor, y: torch.Tensor, x_lengths: torch.Tensor, y_lengths: torch.Tensor,
                  workers: int) -> torch.Tensor:
    from scipy.spatial import cKDTree

    xs = x.detach().cpu().double().numpy()
    ys = y.detach().cpu().double().numpy()
    out = np.zeros(x.shape[:2], dtype=np.int64)
    for row, (n, m) in enumerate(zip(x_lengths.tolist(), y_lengths.tolist())):
        out[row, :n] = cKDTree(ys[row, :m]).query(xs[row, :n], k=1, workers=workers)[1]
    return torch.from_numpy(out).to(x.device)


def nearest(x: torch.Tensor, y: torch.Tensor, x_lengths: torch.Tensor | None = None,
            y_lengths: torch.Tensor | None = None, *, backend: str = "auto", max_pairs: int = MAX_PAIRS,
            workers: int = -1) -> Neighbours:
    """Each point of ``x (B, N, 3)``'s nearest point in ``y (B, M, 3)`` (same batch row), Euclidean.

    Args:
        x_lengths, y_lengths: ``(B,)`` real points per row (ragged batches), default all.
        backend: ``"auto"``, ``"cdist"`` or ``"kdtree"`` (module doc); the indices agree up to exact ties.
        max_pairs: distances the cdist backend holds at once.
        workers: threads of the KD-tree queries (-1: all cores).

    Returns:
        :class:`Neighbours` ``(distance (B, N), index (B, N))``, distances in ``x``'s dtype, on its device.
    """
    if backend not in BACKENDS:
        raise ValueError(f"backend={backend!r}: expected one of {BACKENDS}")
    xl, yl = cloud_lengths(x, x_lengths, "x"), cloud_lengths(y, y_lengths, "y")
    if x.shape[0] != y.shape[0]:
        raise ValueError(f"x and y: batch sizes {x.shape[0]} and {y.shape[0]} differ")
    if backend == "auto":
        backend = "kdtree" if x.device.type == "cpu" and y.device.type == "cpu" else "cdist"
    y = y.to(x.dtype)
    if backend == "cdist":
        index = _index_cdist(x, y, yl, max_pairs)
    else:
        index = _index_kdtree(x, y, xl, yl, workers)
    index = index.masked_fill(~valid_mask(xl, x.shape[1]), 0)
    matched = torch.gather(y, 1, index[..., None].expand(-1, -1, 3))  # (B, N, 3)
    distance = torch.linalg.vector_norm(x - matched, dim=-1)
    return Neighbours(distance.masked_fill(~valid_mask(xl, x.shape[1]), 0.0), index)


__all__ = ["BACKENDS", "MAX_PAIRS", "Neighbours", "cloud_lengths", "nearest", "valid_mask"]
