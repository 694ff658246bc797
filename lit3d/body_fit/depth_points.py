"""A depth image as the fit sees it: camera-frame foreground points and a silhouette distance map.

Camera frame (as :mod:`lit3d.sensing.camera`, whose :func:`~lit3d.sensing.camera.backproject` this
uses): ``x`` right, ``y`` down, ``z`` forward, metres; pixel ``(u, v)`` (column, row) has its centre
at ``(u, v)``: a point projects to ``u = fx x / z + cx``, ``v = fy y / z + cy``. ``intr`` is any
object with ``fx fy cx cy`` attributes (:class:`lit3d.sensing.camera.Intrinsics`).

    obs = observe(depth, intr, keep, label="scan.png")   # Observation
    obs.points       (N, 3) float64   every foreground pixel, back-projected
    obs.sample       (M, 3) float32   at most ``max_points`` of them (seeded), for the loss
    obs.outside_px   (H, W) float32   pixels from each pixel to the silhouette (0 inside it)
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lit3d.body_fit.errors import BodyFitError
from lit3d.sensing.camera import backproject

MIN_POINTS = 200  # fewer foreground pixels than this: no body is fitted
MAX_POINTS = 1500  # points the loss uses per iteration


@dataclass
class Observation:
    """One depth image prepared for the fit (see the module doc)."""

    points: np.ndarray      # (N, 3) float64, camera frame, metres
    sample: np.ndarray      # (M, 3) float32, M <= MAX_POINTS, a seeded subset of points
    mask: np.ndarray        # (H, W) bool foreground
    outside_px: np.ndarray  # (H, W) float32 distance (pixels) to the nearest foreground pixel
    fx: float
    fy: float
    cx: float
    cy: float
    label: str

    @property
    def shape(self) -> tuple[int, int]:
        return self.mask.shape


def foreground(depth: np.ndarray, keep: np.ndarray | None = None) -> np.ndarray:
    """``(H, W) bool``: pixels with a depth reading (``depth > 0``), within ``keep`` when given."""
    fg = np.asarray(depth) > 0
    return fg if keep is None else fg & np.asarray(keep, bool)


def subsample(points: np.ndarray, n: int, seed: int = 0) -> np.ndarray:
    """At most ``n`` rows of ``points`` ``(N, 3)``, drawn without replacement (seeded), float32."""
    if len(points) <= n:
        return points.astype(np.float32)
    idx = np.random.default_rng(seed).choice(len(points), n, replace=False)
    return points[np.sort(idx)].astype(np.float32)


def outside_distance(mask: np.ndarray) -> np.ndarray:
    """``(H, W) float32``: Euclidean distance in pixels from each pixel to the nearest ``mask``
    pixel (0 on the mask)."""
    from scipy import ndimage

    return ndimage.distance_transform_edt(~mask).astype(np.float32)


def observe(depth: np.ndarray, intr, keep: np.ndarray | None = None, label: str = "<depth>",
            max_points: int = MAX_POINTS) -> Observation:
    """Prepare ``(H, W)`` depth (metres, 0 = background) for the fit; ``keep``: optional
    ``(H, W) bool`` object pixels (a mask, depth range, plane removal). Raises
    :class:`BodyFitError` with fewer than :data:`MIN_POINTS` foreground pixels."""
    mask = foreground(depth, keep)
    n = int(mask.sum())
    if n < MIN_POINTS:
        raise BodyFitError(f"{label}: {n} foreground depth pixels; a body fit needs at least {MIN_POINTS} "
                           "(no person in the image, or cut away by the mask/depth range?)")
    pts = backproject(depth, intr, mask)
    return Observation(pts, subsample(pts, max_points), mask, outside_distance(mask),
                       float(intr.fx), float(intr.fy), float(intr.cx), float(intr.cy), label)
