"""Non-learned canonical forms of full meshes (thesis 5.4 baselines).

    canonical_forms(meshes, "cmds")            [(verts, faces)] -> [(embedded verts, faces)]
    canonical_forms_multi(meshes, methods)     several methods, geodesics computed once per mesh

Methods: ``cmds``/``smacof``/``nmds`` (:mod:`lit3d.geometry.mds` of
:mod:`lit3d.geometry.geodesics`), ``gps`` (:mod:`lit3d.geometry.spectral`), ``posed``
(unchanged). Dense geodesic matrices are V x V, so meshes are first decimated to
``max_vertices`` (:func:`lit3d.geometry.simplify.simplify_to_vertices`). The embeddings
replace the vertex positions of the same faces, so the results are meshes that go through
the same retrieval descriptor as everything else.
"""
from __future__ import annotations

import numpy as np

from lit3d.geometry.geodesics import geodesic_matrix
from lit3d.geometry.mds import classical_mds, nonmetric_mds, smacof_mds
from lit3d.geometry.simplify import simplify_to_vertices
from lit3d.geometry.spectral import gps_embedding


METHODS = ("cmds", "smacof", "nmds", "gps", "posed")


def canonical_form(v: np.ndarray, f: np.ndarray, method: str, D: np.ndarray | None = None,
                   max_iter: int = 300, eps: float = 1e-6) -> np.ndarray:
    """Embedded vertices ``(V, 3)`` of one (already simplified) mesh; ``posed`` returns it unchanged."""
    if method == "cmds":
        return classical_mds(v, f, D=D)
    if method == "smacof":
        return smacof_mds(v, f, D=D, max_iter=max_iter, eps=eps)
    if method == "nmds":
        return nonmetric_mds(v, f, D=D, max_iter=max_iter)
    if method == "gps":
        return gps_embedding(v, f)
    if method == "posed":
        return v
    raise ValueError(f"unknown canonical baseline '{method}' ({', '.join(METHODS)})")


def canonical_forms(meshes, method: str, max_vertices: int = 1500) -> list[tuple[np.ndarray, np.ndarray]]:
    """``[(verts, faces)] -> [(embedded verts, faces)]`` for method in cmds, smacof, nmds, gps, posed."""
    return canonical_forms_multi(meshes, [method], max_vertices)[method]


def canonical_forms_multi(meshes, methods, max_vertices: int = 1500, max_iter: int = 300,
                          eps: float = 1e-6) -> dict[str, list[tuple[np.ndarray, np.ndarray]]]:
    """Several baselines at once: each mesh is simplified once and its geodesic matrix computed
    once (shared by cmds, smacof and nmds). Returns ``{method: [(embedded verts, faces), ...]}``."""
    methods = list(methods)
    bad = [m for m in methods if m not in METHODS]
    if bad:
        raise ValueError(f"unknown canonical baseline(s) {bad} ({', '.join(METHODS)})")
    out: dict[str, list] = {m: [] for m in methods}
    needs_geo = any(m in ("cmds", "smacof", "nmds") for m in methods)
    for v, f in meshes:
        v, f = simplify_to_vertices(np.asarray(v, float), np.asarray(f, np.int64), max_vertices)
        D = geodesic_matrix(v, f) if needs_geo else None
        for m in methods:
            out[m].append((canonical_form(v, f, m, D=D, max_iter=max_iter, eps=eps), f))
    return out
