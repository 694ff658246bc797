"""The one mesh simplifier of lit3d: quadric edge-collapse decimation (``fast_simplification``).

    v, f = simplify(verts, faces, target_faces=2000)          # about 2000 faces
    v, f = simplify_to_vertices(verts, faces, max_vertices=1500)   # at most 1500 vertices

Used by the quality distortion levels (:mod:`datamodules.quality.distortions`) and the
canonical-form baselines (:mod:`lit3d.geometry.canonical_forms`, dense ``V x V`` geodesics).
"""
from __future__ import annotations

import logging

import numpy as np

log = logging.getLogger(__name__)


def simplify(verts: np.ndarray, faces: np.ndarray, target_faces: int) -> tuple[np.ndarray, np.ndarray]:
    """Quadric decimation to about ``target_faces`` faces.

    Args:
        verts: ``(V, 3)`` float vertex positions.
        faces: ``(F, 3)`` int triangle indices.
        target_faces: wanted face count (meshes with fewer faces come back unchanged by the library).

    Returns:
        ``(V', 3) float64`` vertices (only those the faces use) and ``(F', 3) int64`` faces.
    """
    from fast_simplification import simplify as decimate

    v, f = decimate(points=np.asarray(verts, dtype=np.float64), triangles=np.asarray(faces, dtype=np.int64),
                    target_count=int(target_faces))
    return np.asarray(v, dtype=np.float64), np.asarray(f, dtype=np.int64)


def simplify_to_vertices(verts: np.ndarray, faces: np.ndarray, max_vertices: int,
                         max_tries: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """Quadric decimation until at most ``max_vertices`` vertices remain.

    The first face target is ``2 * (max_vertices - 2)`` (Euler: a closed genus-0 mesh has
    ``V = F / 2 + 2``); open or higher-genus meshes keep more vertices per face, so the
    target shrinks in proportion until the vertex count fits. Each try decimates the input
    mesh afresh (deterministic).

    Args:
        verts: ``(V, 3)`` float vertex positions.
        faces: ``(F, 3)`` int triangle indices.
        max_vertices: vertex budget.
        max_tries: decimations tried before giving up.

    Returns:
        ``(V', 3) float64`` vertices and ``(F', 3) int64`` faces; the input unchanged when
        ``V <= max_vertices``.

    Quadric decimation can stall above the budget (e.g. on meshes of long sliver triangles);
    then the smallest result reached is returned and a warning logged.
    """
    if len(verts) <= max_vertices:
        return verts, faces
    target = max(2 * (max_vertices - 2), 4)
    best = (verts, faces)
    for _ in range(max_tries):
        v, f = simplify(verts, faces, target)
        if len(v) < len(best[0]):
            best = (v, f)
        if len(v) <= max_vertices:
            return v, f
        target = max(int(target * max_vertices / len(v)) - 1, 4)
    log.warning("quadric decimation stalled at %d of %d vertices (budget %d)", len(best[0]), len(verts), max_vertices)
    return best
