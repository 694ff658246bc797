"""3-D shape distances on surface samples: Chamfer and Hausdorff (scipy cKDTree).

Both meshes are centred and scaled to a unit bounding box first (as for the
renders), then ``n`` points are sampled uniformly on each surface with a fixed
seed, so the numbers are in units of the bounding-box side and repeatable.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from lit3d.render.convert import normalise as _normalise


def surface_samples(mesh, n: int = 20000, seed: int = 0, normalise: bool = True) -> np.ndarray:
    """``(n, 3) float64`` points sampled uniformly (by area) on ``mesh``'s surface."""
    import trimesh

    m = _normalise(mesh) if normalise else mesh
    pts, _ = trimesh.sample.sample_surface(m, n, seed=seed)
    return np.asarray(pts, dtype=np.float64)


def directed_distances(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance from every point of ``a (N, 3)`` to its nearest point in ``b (M, 3)``: ``(N,)``."""
    return cKDTree(b).query(a, k=1, workers=-1)[0]


def chamfer_hausdorff(mesh_a, mesh_b, n: int = 20000, seed: int = 0) -> dict[str, float]:
    """Symmetric Chamfer and Hausdorff distances between two meshes.

    Returns:
        ``{"chamfer": 0.5 * (mean d(A->B) + mean d(B->A)),
        "hausdorff": max(max d(A->B), max d(B->A))}`` on normalised meshes.
    """
    pa = surface_samples(mesh_a, n, seed)
    pb = surface_samples(mesh_b, n, seed + 1)
    dab = directed_distances(pa, pb)
    dba = directed_distances(pb, pa)
    return {"chamfer": float(0.5 * (dab.mean() + dba.mean())), "hausdorff": float(max(dab.max(), dba.max()))}


def chamfer(mesh_a, mesh_b, n: int = 20000, seed: int = 0) -> float:
    """Symmetric mean nearest-neighbour distance (see :func:`chamfer_hausdorff`)."""
    return chamfer_hausdorff(mesh_a, mesh_b, n, seed)["chamfer"]


def hausdorff(mesh_a, mesh_b, n: int = 20000, seed: int = 0) -> float:
    """Symmetric Hausdorff distance on surface samples (see :func:`chamfer_hausdorff`)."""
    return chamfer_hausdorff(mesh_a, mesh_b, n, seed)["hausdorff"]
