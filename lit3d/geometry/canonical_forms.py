"""Non-learned canonical forms of full meshes (thesis 5.4 baselines).

    canonical_forms(meshes, "cmds")            [(verts, faces)] -> [(embedded verts, faces)]
    canonical_forms_multi(meshes, methods)     several methods, geodesics computed once per mesh

Methods: ``cmds``/``smacof``/``nmds`` (:mod:`lit3d.geometry.mds` of
:mod:`lit3d.geometry.geodesics`), ``gps`` (:mod:`lit3d.geometry.spectral`), ``posed``
(unchanged). Meshes stay at full resolution: with ``landmarks=L`` and more than ``L``
vertices, geodesics come from ``L`` farthest-point landmarks (heat method on the full mesh) and
every vertex is placed by landmark MDS / triangulation; otherwise the dense ``V x V`` matrix is
used. ``max_vertices`` (default off) decimates first
(:func:`lit3d.geometry.simplify.simplify_to_vertices`): the old, handicapped setting (vertex
collapses fuse parts and make geodesic shortcuts). The embeddings replace the vertex positions
of the same faces, so the results are meshes that go through the same retrieval descriptor as
everything else.
"""
from __future__ import annotations

import numpy as np

from lit3d.geometry.geodesics import geodesic_matrix, landmark_geodesics
from lit3d.geometry.mds import landmark_mds, landmark_nmds, landmark_smacof
from lit3d.geometry.simplify import simplify_to_vertices
from lit3d.geometry.spectral import gps_embedding
from lit3d.utils.progress import progress

METHODS = ("cmds", "smacof", "nmds", "gps", "posed")
GEODESIC_METHODS = ("cmds", "smacof", "nmds")


def mesh_geodesics(v: np.ndarray, f: np.ndarray, landmarks: int | None) -> tuple[np.ndarray, np.ndarray]:
    """``(idx (L,), D (L, V))``: landmark rows when ``landmarks`` is set and smaller than ``V``,
    else every vertex (the dense symmetric matrix, ``idx = arange(V)``)."""
    if landmarks and len(v) > landmarks:
        return landmark_geodesics(v, f, landmarks)
    return np.arange(len(v)), geodesic_matrix(v, f)


def canonical_form(v: np.ndarray, f: np.ndarray, method: str, geo: tuple[np.ndarray, np.ndarray] | None = None,
                   max_iter: int = 300, eps: float = 1e-6, landmarks: int | None = 300) -> np.ndarray:
    """Embedded vertices ``(V, 3)`` of one mesh; ``posed`` returns it unchanged. ``geo``: the
    ``(idx, D)`` of :func:`mesh_geodesics` (computed when None and needed)."""
    if method not in METHODS:
        raise ValueError(f"unknown canonical baseline '{method}' ({', '.join(METHODS)})")
    if method == "gps":
        return gps_embedding(v, f)
    if method == "posed":
        return v
    idx, D = geo if geo is not None else mesh_geodesics(v, f, landmarks)
    if method == "cmds":
        return landmark_mds(D, idx)
    if method == "smacof":
        return landmark_smacof(D, idx, max_iter=max_iter, eps=eps)
    return landmark_nmds(D, idx, max_iter=max_iter)


def canonical_forms(meshes, method: str, max_vertices: int | None = None,
                    landmarks: int | None = 300) -> list[tuple[np.ndarray, np.ndarray]]:
    """``[(verts, faces)] -> [(embedded verts, faces)]`` for method in cmds, smacof, nmds, gps, posed."""
    return canonical_forms_multi(meshes, [method], max_vertices, landmarks=landmarks)[method]


def canonical_forms_multi(meshes, methods, max_vertices: int | None = None, max_iter: int = 300,
                          eps: float = 1e-6, landmarks: int | None = 300) -> dict[str, list[tuple[np.ndarray, np.ndarray]]]:
    """Several baselines at once: geodesics computed once per mesh (shared by cmds, smacof and
    nmds). Returns ``{method: [(embedded verts, faces), ...]}``."""
    methods = list(methods)
    bad = [m for m in methods if m not in METHODS]
    if bad:
        raise ValueError(f"unknown canonical baseline(s) {bad} ({', '.join(METHODS)})")
    out: dict[str, list] = {m: [] for m in methods}
    needs_geo = any(m in GEODESIC_METHODS for m in methods)
    for v, f in progress(meshes, f"canonical forms ({', '.join(methods)})"):  # a line every 10 s
        v, f = np.asarray(v, float), np.asarray(f, np.int64)
        if max_vertices:
            v, f = simplify_to_vertices(v, f, max_vertices)
        geo = mesh_geodesics(v, f, landmarks) if needs_geo else None
        for m in methods:
            out[m].append((canonical_form(v, f, m, geo=geo, max_iter=max_iter, eps=eps), f))
    return out
