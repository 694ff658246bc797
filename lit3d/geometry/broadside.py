"""Camera conventions for the canonical task's depth images: which azimuth about the up (+y)
axis a shape is seen from.

    az = broadside_azimuth(verts, faces)     # degrees; rotate_y(verts, az) shows the broad side

``fixed`` (the old convention) renders every shape at azimuth 0: a quadruped whose body runs
along the viewing axis is seen end-on (a TOSCA cat covered 4.7% of the pixels). ``broadside``
turns each shape so that its horizontal axis of greatest extent (area-weighted principal axis
of the surface projected on the ground plane) lies across the image and the camera looks along
the axis of least extent. It needs only the shape in front of the camera, so at inference a
camera (or a person) can be placed the same way for a posed subject; the canonical target is
rendered by the same rule from the canonical shape. The sign of the axis (which of the two
broad sides) is fixed by the skew of the surface along it; a mirror view remains possible,
which is what left-right flip augmentation (``data.training.flip_lr``) covers.
"""
from __future__ import annotations

import math

import numpy as np

VIEW_MODES = ("fixed", "broadside")


def broadside_azimuth(verts: np.ndarray, faces: np.ndarray) -> float:
    """Azimuth in degrees (for :func:`lit3d.render.depth.rotate_y`) that puts the horizontal
    principal axis of greatest extent of ``verts`` ``(V, 3)`` (y up; ``faces`` ``(F, 3)`` give the
    area weights) along the image x axis, its skewed end towards +x."""
    tri = np.asarray(verts, np.float64)[np.asarray(faces, np.int64)]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    w = area / max(area.sum(), 1e-12)
    p = tri.mean(1)[:, [0, 2]]  # ground-plane (x, z) of each face centre
    p = p - (w[:, None] * p).sum(0)
    _, vecs = np.linalg.eigh((w[:, None, None] * p[:, :, None] * p[:, None, :]).sum(0))
    ex, ez = vecs[:, -1]
    if (w * (p @ vecs[:, -1]) ** 3).sum() < 0:
        ex, ez = -ex, -ez
    # rotate_y maps (x, z) -> (c x + s z, -s x + c z): the axis (ex, ez) goes to +x for a = atan2(ez, ex)
    return math.degrees(math.atan2(ez, ex))


def base_azimuth(verts: np.ndarray, faces: np.ndarray, mode: str) -> float:
    """The convention's azimuth of one shape: 0 for ``fixed``, :func:`broadside_azimuth` for
    ``broadside``; the configured ``azimuths`` are added to it."""
    if mode == "fixed":
        return 0.0
    if mode == "broadside":
        return broadside_azimuth(verts, faces)
    raise ValueError(f"unknown view mode '{mode}' ({', '.join(VIEW_MODES)})")
