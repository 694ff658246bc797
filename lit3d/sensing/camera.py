"""Pinhole intrinsics, back-projection of a depth image to camera-frame points, and projection.

Shared by ``lit3d-reconstruct`` (:mod:`lit3d.reconstruct.backproject` re-exports these names) and
the body fit (:mod:`lit3d.body_fit`).

Camera frame (OpenCV / depth-sensor convention): ``x`` right, ``y`` down in the image,
``z`` forward along the optical axis, in metres. Pixel ``(u, v)`` (column, row) has its
centre at image coordinates ``(u, v)``; a point projects to ``u = fx x / z + cx``,
``v = fy y / z + cy``.

The default camera is 3D-RecGAN++'s (``Data_preprocess/depth_2_pc_2_vox.py`` of its release):
a field of view of 49.124 degrees across both the width and the height of the image,
``fx = W / (2 tan(fov / 2))``, ``fy = H / (2 tan(fov / 2))``, ``cx = W / 2``, ``cy = H / 2``
(:data:`lit3d.sensing.sensor.RECGAN_FOV_DEG`).
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import ClassVar

import numpy as np

from lit3d.utils.errors import Lit3dError


class CameraError(Lit3dError, ValueError):
    """Intrinsics that cannot describe an image (a field of view outside (0, 180) degrees, a
    focal length that is not positive, a principal point outside the image): one line."""


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics in pixels (see the module doc for the convention). ``error``: the class
    its checks raise (a user of the shared camera may name its own, e.g. lit3d-reconstruct's
    ``InputError``)."""

    fx: float
    fy: float
    cx: float
    cy: float
    error: ClassVar[type[Exception]] = CameraError

    @classmethod
    def from_fov(cls, fov_deg: float, width: int, height: int) -> "Intrinsics":
        """3D-RecGAN++-style intrinsics: one field of view across both image sides, centred."""
        if not 0 < fov_deg < 180:
            raise cls.error(f"--fov {fov_deg}: expected a field of view in (0, 180) degrees")
        t = 2.0 * math.tan(math.radians(fov_deg) / 2)
        return cls(width / t, height / t, width / 2.0, height / 2.0)

    def check(self, width: int, height: int, label: str = "intrinsics") -> "Intrinsics":
        """Raise :attr:`error` unless the focal lengths are positive and finite and the
        principal point lies inside the ``width x height`` image."""
        vals = asdict(self)
        if not all(np.isfinite(v) for v in vals.values()):
            raise self.error(f"{label}: intrinsics must be finite numbers, got {vals}")
        if self.fx <= 0 or self.fy <= 0:
            raise self.error(f"{label}: focal lengths must be positive (fx={self.fx:g}, fy={self.fy:g} px)")
        if not (0 <= self.cx <= width and 0 <= self.cy <= height):
            raise self.error(f"{label}: principal point ({self.cx:g}, {self.cy:g}) lies outside the "
                             f"{width}x{height} image (wrong intrinsics for this image size?)")
        return self

    def as_dict(self) -> dict:
        return {k: float(v) for k, v in asdict(self).items()}


def backproject(depth: np.ndarray, intr, keep: np.ndarray | None = None) -> np.ndarray:
    """Foreground pixels -> ``(N, 3) float64`` camera-frame points in metres.

    Args:
        depth: ``(H, W)`` metres along the optical axis (z), 0 = background.
        intr: the camera (:class:`Intrinsics`, or any object with ``fx fy cx cy``).
        keep: optional ``(H, W) bool``: only these pixels (and ``depth > 0``) are used.
    """
    depth = np.asarray(depth)
    sel = depth > 0 if keep is None else np.asarray(keep, bool) & (depth > 0)
    v, u = np.nonzero(sel)
    z = depth[v, u].astype(np.float64)
    return np.stack([(u - intr.cx) * z / intr.fx, (v - intr.cy) * z / intr.fy, z], axis=1)


def pixel_coordinates(x, y, z, intr):
    """The pinhole projection ``(u, v)`` of camera-frame coordinates ``x, y, z`` ``(N,)`` (z > 0), NumPy arrays
    or torch tensors alike (differentiable for tensors); ``intr``: anything with fx, fy, cx, cy."""
    return intr.fx * x / z + intr.cx, intr.fy * y / z + intr.cy


def project(points: np.ndarray, intr) -> np.ndarray:
    """``(N, 3)`` camera-frame points (z > 0) -> ``(N, 2) float64`` pixel coordinates ``(u, v)``."""
    return np.stack(pixel_coordinates(points[:, 0], points[:, 1], points[:, 2], intr), axis=1)
