"""The canonical task's depth images: the one orthographic camera (:mod:`lit3d.render.camera`)
on +z looking down -z, depth normalised to [0, 1].

Shapes are centred and scaled to a unit bounding box; the camera sits at distance 2, so
visible surfaces lie at camera distances [1.5, 2.5], which map linearly to depths
[1, 0.1] (nearer = larger); background = 0.

    depth, mask = render_depth(verts, faces, size=128)         # (S, S) float32, (S, S) bool
    verts, faces = depth_to_mesh(depth, mask)                   # back-projected surface
"""
from __future__ import annotations

import math

import numpy as np

from lit3d.render.camera import OrthoCamera, look_at, render_ortho_depth

CAMERA_DISTANCE = 2.0
ORTHO_MAG = 0.55  # half the visible width: the unit box fills 91% of the image
DEPTH_NEAR, DEPTH_FAR = CAMERA_DISTANCE - 0.5, CAMERA_DISTANCE + 0.5
FG_MIN = 0.1
Z_NEAR, Z_FAR = 0.5, 3.5
CAMERA = OrthoCamera(half_width=ORTHO_MAG, znear=Z_NEAR, zfar=Z_FAR)


def rotate_y(verts: np.ndarray, deg: float) -> np.ndarray:
    """Turn ``(N, 3)`` points by ``deg`` degrees about the y (up) axis."""
    a = math.radians(deg)
    c, s = math.cos(a), math.sin(a)
    return verts @ np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]).T



def render_depth(verts: np.ndarray, faces: np.ndarray, size: int, azimuth: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Normalised depth ``(S, S) float32`` in [0, 1] and mask ``(S, S) bool`` of a normalised mesh."""
    v = rotate_y(verts, azimuth) if azimuth else verts
    dist, mask = render_ortho_depth(v, faces, look_at([0.0, 0.0, CAMERA_DISTANCE]), size, CAMERA)
    depth = np.zeros(dist.shape, dtype=np.float32)
    depth[mask] = np.clip(1 - (1 - FG_MIN) * (dist[mask] - DEPTH_NEAR) / (DEPTH_FAR - DEPTH_NEAR), FG_MIN, 1)
    return depth, mask


def project_points(verts: np.ndarray, size: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where this camera sees ``(N, 3)`` world points in an ``S x S`` image: column and row
    ``(N,)`` in pixels (pixel centres at integers, row 0 = top; the inverse of :func:`pixel_grid`)
    and their normalised depth ``(N,)`` (as :func:`render_depth` writes it, unclipped)."""
    v = np.asarray(verts, np.float64)
    col = (v[:, 0] / ORTHO_MAG + 1) / 2 * size - 0.5
    row = (1 - v[:, 1] / ORTHO_MAG) / 2 * size - 0.5
    dist = CAMERA_DISTANCE - v[:, 2]
    return col, row, 1 - (1 - FG_MIN) * (dist - DEPTH_NEAR) / (DEPTH_FAR - DEPTH_NEAR)


def depth_to_distance(depth: np.ndarray) -> np.ndarray:
    """Inverse of the depth normalisation: camera distance of each foreground pixel."""
    return DEPTH_NEAR + (1 - depth) * (DEPTH_FAR - DEPTH_NEAR) / (1 - FG_MIN)


def pixel_grid(h: int, w: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """World x, y ``(H, W)`` of each pixel centre (row 0 = top) for this camera."""
    w = w or h
    cx = ((np.arange(w) + 0.5) / w * 2 - 1) * ORTHO_MAG
    cy = -((np.arange(h) + 0.5) / h * 2 - 1) * ORTHO_MAG
    return np.meshgrid(cx, cy)


def depth_to_points(depth: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Back-project a normalised depth image + mask to ``(N, 3)`` world points (N = mask pixels)."""
    m = (mask > 0.5) & (depth > 0)
    x, y = pixel_grid(*depth.shape)
    z = CAMERA_DISTANCE - depth_to_distance(depth)
    return np.stack([x[m], y[m], z[m]], 1)


def depth_to_mesh(depth: np.ndarray, mask: np.ndarray, max_jump: float = 0.08) -> tuple[np.ndarray, np.ndarray]:
    """Back-project to a triangle mesh: two triangles per 2x2 block of foreground pixels whose
    depths differ by less than ``max_jump`` (normalised units). Faces face the camera (+z).
    Returns ``(V, 3) float64, (F, 3) int64``; empty arrays when the mask is empty."""
    h, w = depth.shape
    m = (mask > 0.5) & (depth > 0)
    x, y = pixel_grid(h, w)
    z = CAMERA_DISTANCE - depth_to_distance(depth)
    idx = -np.ones((h, w), dtype=np.int64)
    idx[m] = np.arange(int(m.sum()))
    verts = np.stack([x[m], y[m], z[m]], 1)
    a, b, c, d = idx[:-1, :-1], idx[:-1, 1:], idx[1:, :-1], idx[1:, 1:]  # tl, tr, bl, br
    da, db, dc, dd = depth[:-1, :-1], depth[:-1, 1:], depth[1:, :-1], depth[1:, 1:]
    faces = []
    for (p, q, r), (dp, dq, dr) in (((a, c, b), (da, dc, db)), ((b, c, d), (db, dc, dd))):
        ok = (p >= 0) & (q >= 0) & (r >= 0)
        ok &= np.maximum(np.maximum(dp, dq), dr) - np.minimum(np.minimum(dp, dq), dr) < max_jump
        faces.append(np.stack([p[ok], q[ok], r[ok]], 1))
    faces = np.concatenate(faces) if faces else np.zeros((0, 3), np.int64)
    return verts, faces.astype(np.int64)
