"""Geodesic distance matrices of triangle meshes.

    D = geodesic_matrix(verts, faces)     # (V, V) float64, symmetric

potpourri3d's heat method when installed; Dijkstra on mesh edges otherwise (overestimates
by about 8-10%).
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra


def geodesic_matrix(verts: np.ndarray, faces: np.ndarray, method: str = "auto") -> np.ndarray:
    """``(V, V)`` geodesic distances: heat method (potpourri3d) or Dijkstra on edges."""
    if method in ("auto", "heat"):
        try:
            import potpourri3d as pp3d

            solver = pp3d.MeshHeatMethodDistanceSolver(verts, faces)
            D = np.stack([solver.compute_distance(i) for i in range(len(verts))])
            return (D + D.T) / 2
        except ImportError:
            if method == "heat":
                raise
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    w = np.linalg.norm(verts[e[:, 0]] - verts[e[:, 1]], axis=1)
    G = sp.coo_matrix((w, (e[:, 0], e[:, 1])), shape=(len(verts),) * 2).tocsr()
    D = dijkstra(G.maximum(G.T), directed=False)
    D[~np.isfinite(D)] = D[np.isfinite(D)].max() if np.isfinite(D).any() else 0
    return D
