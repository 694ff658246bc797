"""Cutting the object out of a depth image: mask, depth range, dominant-plane removal.

Every function works on pixel masks ``(H, W) bool`` so that the choices compose and the
figure can show what was kept.
"""
from __future__ import annotations

import numpy as np

from lit3d.reconstruct.backproject import Intrinsics, backproject


def depth_range_mask(depth: np.ndarray, near: float | None = None, far: float | None = None) -> np.ndarray:
    """``(H, W) bool``: foreground pixels with ``near <= depth <= far`` (metres; None = open)."""
    keep = depth > 0
    if near is not None:
        keep &= depth >= near
    if far is not None:
        keep &= depth <= far
    return keep


def remove_plane(depth: np.ndarray, intr: Intrinsics, keep: np.ndarray, tolerance: float = 0.01,
                 iterations: int = 200, min_share: float = 0.15, seed: int = 0) -> tuple[np.ndarray, dict]:
    """Drop the dominant plane (a table or floor) from ``keep`` with RANSAC.

    Args:
        depth: ``(H, W) float32`` metres.
        intr: the camera.
        keep: ``(H, W) bool`` pixels considered so far.
        tolerance: point-to-plane distance (metres) counted as on the plane.
        iterations: RANSAC hypotheses.
        min_share: the plane is removed only when it holds at least this share of the points
            (else the object itself may be mostly flat: nothing is removed).
        seed: random seed (the result is deterministic).

    Returns:
        ``(keep without the plane's pixels, info)``; ``info`` has the plane ``normal`` (unit,
        camera frame), ``offset`` (metres, ``n . p = offset``) and ``removed`` pixel count.
    """
    pts = backproject(depth, intr, keep)
    if len(pts) < 3:
        return keep, {"removed": 0}
    rng = np.random.default_rng(seed)
    sample = pts if len(pts) <= 20000 else pts[rng.choice(len(pts), 20000, replace=False)]
    best, best_n, best_d = -1, None, 0.0
    for _ in range(iterations):
        a, b, c = sample[rng.choice(len(sample), 3, replace=False)]
        n = np.cross(b - a, c - a)
        norm = np.linalg.norm(n)
        if norm < 1e-12:
            continue
        n /= norm
        d = float(n @ a)
        count = int((np.abs(sample @ n - d) < tolerance).sum())
        if count > best:
            best, best_n, best_d = count, n, d
    if best_n is None or best < min_share * len(sample):
        return keep, {"removed": 0}
    on_plane = np.abs(pts @ best_n - best_d) < tolerance
    out = keep & (depth > 0)
    rows, cols = np.nonzero(out)
    out[rows[on_plane], cols[on_plane]] = False
    return out, {"normal": best_n.tolist(), "offset": best_d, "removed": int(on_plane.sum())}


def largest_depth_cluster(depth: np.ndarray, keep: np.ndarray, gap: float = 0.05) -> np.ndarray:
    """The 4-connected region of ``keep`` holding the most pixels, neighbours joined only where
    their depths differ by less than ``gap`` metres (drops stray background pixels)."""
    from scipy import ndimage

    d = np.where(keep, depth, 0.0)
    smooth_x = np.abs(np.diff(d, axis=1)) < gap
    smooth_y = np.abs(np.diff(d, axis=0)) < gap
    # cut the mask along depth jumps, then label
    cut = keep.copy()
    cut[:, 1:] &= ~(~smooth_x & keep[:, :-1] & (d[:, 1:] > d[:, :-1]))
    cut[1:, :] &= ~(~smooth_y & keep[:-1, :] & (d[1:, :] > d[:-1, :]))
    labels, n = ndimage.label(cut)
    if n <= 1:
        return cut if n == 1 else keep
    sizes = np.bincount(labels.ravel())[1:]
    return labels == (1 + int(np.argmax(sizes)))
