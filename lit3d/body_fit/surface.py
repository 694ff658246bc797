"""The fit's geometric loss terms on camera-frame body vertices ``(V, 3)`` (see :mod:`lit3d.body_fit.fit`).

- :func:`point_to_surface`: observed points -> the nearest front-facing vertex, a mix of the
  point-to-vertex and point-to-plane distances (approximates the point-to-triangle distance);
- :func:`silhouette_excess`: projected vertices -> how far (metres) outside the foreground mask.
"""
from __future__ import annotations

import numpy as np
import torch

from lit3d.body_fit.depth_points import Observation
from lit3d.sensing.camera import pixel_coordinates


def vertex_normals(verts: np.ndarray, faces: np.ndarray, incidence=None) -> np.ndarray:
    """``(V, 3)`` unit area-weighted vertex normals of a mesh ``(V, 3)``, ``(F, 3)``;
    ``incidence``: the ``(V, F)`` sparse vertex-face matrix (:func:`incidence_matrix`), if built."""
    tri = verts[faces]
    fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    vn = (incidence if incidence is not None else incidence_matrix(faces, len(verts))) @ fn
    return vn / np.maximum(np.linalg.norm(vn, axis=1, keepdims=True), 1e-12)


def incidence_matrix(faces: np.ndarray, n_verts: int):
    """``(V, F)`` scipy sparse matrix, 1 where a vertex is a corner of a face."""
    from scipy import sparse

    rows = np.asarray(faces).T.ravel()
    cols = np.tile(np.arange(len(faces)), 3)
    return sparse.csr_matrix((np.ones(len(rows)), (rows, cols)), shape=(n_verts, len(faces)))


def visible_matches(verts: torch.Tensor, faces: np.ndarray, points: np.ndarray,
                    incidence=None) -> tuple[torch.Tensor, torch.Tensor]:
    """For ``points`` ``(M, 3)``: index ``(M,)`` of the nearest front-facing vertex of ``verts``
    ``(V, 3)`` (camera at the origin) and that vertex's normal ``(M, 3)`` (no gradient)."""
    from scipy.spatial import cKDTree

    v = verts.detach().double().numpy()
    n = vertex_normals(v, faces, incidence)
    front = np.nonzero((n * v).sum(1) < 0)[0]
    if len(front) == 0:  # a body seen from behind its own normals: use every vertex
        front = np.arange(len(v))
    _, k = cKDTree(v[front]).query(points)
    idx = front[k]
    return torch.from_numpy(idx), torch.from_numpy(n[idx]).float()


def point_to_surface(verts: torch.Tensor, faces: np.ndarray, points: torch.Tensor, mix: float,
                     incidence=None) -> torch.Tensor:
    """``(M,)`` distances (metres) from ``points`` ``(M, 3)`` to the visible surface of ``verts``."""
    idx, nrm = visible_matches(verts, faces, points.numpy(), incidence)
    diff = points - verts[idx]
    sq = mix * (diff * diff).sum(1) + (1 - mix) * (diff * nrm).sum(1) ** 2
    return torch.sqrt(sq + 1e-8)


def silhouette_excess(verts: torch.Tensor, obs: Observation, outside: torch.Tensor) -> torch.Tensor:
    """``(V,)`` metres by which each projected vertex lies outside the silhouette (0 inside);
    ``outside`` is ``obs.outside_px`` as a ``(1, 1, H, W)`` tensor."""
    h, w = obs.shape
    z = verts[:, 2].clamp(min=1e-3)
    u, v = pixel_coordinates(verts[:, 0], verts[:, 1], z, obs)
    grid = torch.stack([u / max(w - 1, 1) * 2 - 1, v / max(h - 1, 1) * 2 - 1], 1)[None, None]
    px = torch.nn.functional.grid_sample(outside, grid, mode="bilinear", padding_mode="border", align_corners=True)
    return px[0, 0, 0] * z / obs.fx
