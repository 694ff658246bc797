"""Non-learned canonical forms of full meshes (thesis 5.4 baselines).

    classical_mds(verts, faces)   classical (Torgerson) MDS of geodesic distances -> (V, 3)
    smacof_mds(verts, faces)      least-squares MDS (SMACOF, scikit-learn) -> (V, 3)
    nonmetric_mds(verts, faces)   non-metric MDS (scikit-learn, 1.8 argument names shimmed) -> (V, 3)
    gps_embedding(verts, faces)   Global Point Signature: cotangent-Laplacian eigenvectors / sqrt(eigenvalue)

Geodesics come from potpourri3d's heat method when installed (Dijkstra on mesh edges
otherwise, which overestimates by about 8-10%). Dense geodesic matrices are V x V, so meshes
are simplified to ``max_vertices`` first (vertex clustering keeps it dependency-free).
The embeddings replace the vertex positions of the same faces, so the results are meshes
that go through the same retrieval descriptor as everything else.
"""
from __future__ import annotations

import inspect

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra
from scipy.sparse.linalg import eigsh


def simplify(verts: np.ndarray, faces: np.ndarray, max_vertices: int = 1500) -> tuple[np.ndarray, np.ndarray]:
    """Vertex clustering on a grid until at most ``max_vertices`` remain; degenerate faces dropped."""
    if len(verts) <= max_vertices:
        return verts, faces
    lo, hi = verts.min(0), verts.max(0)
    ext = float((hi - lo).max())
    cells = int(np.sqrt(max_vertices) * 2)
    while True:
        q = np.floor((verts - lo) / ext * cells).astype(np.int64)
        _, inv = np.unique(q, axis=0, return_inverse=True)
        inv = inv.ravel()
        n = inv.max() + 1
        if n <= max_vertices or cells <= 4:
            break
        cells = int(cells * 0.85)
    sums = np.zeros((n, 3))
    np.add.at(sums, inv, verts)
    v = sums / np.bincount(inv, minlength=n)[:, None]
    f = inv[faces]
    f = f[(f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 0] != f[:, 2])]
    f = np.unique(np.sort(f, axis=1), axis=0) if len(f) else f
    used = np.unique(f)
    remap = -np.ones(n, np.int64)
    remap[used] = np.arange(len(used))
    return v[used], remap[f]


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


def classical_mds(verts, faces, dim: int = 3, D: np.ndarray | None = None) -> np.ndarray:
    """Torgerson MDS: double-centred squared geodesics, top eigenvectors scaled by sqrt(eigenvalue)."""
    D = geodesic_matrix(verts, faces) if D is None else D
    n = len(D)
    J = np.eye(n) - 1.0 / n
    B = -0.5 * J @ (D ** 2) @ J
    vals, vecs = np.linalg.eigh(B)
    order = np.argsort(vals)[::-1][:dim]
    return vecs[:, order] * np.sqrt(np.maximum(vals[order], 0))


def _mds_estimator(dim: int, seed: int, max_iter: int, metric: bool = True):
    """scikit-learn MDS on a precomputed dissimilarity, across the 1.8 argument rename
    (``metric_mds=`` / ``metric="precomputed"`` from 1.8; ``metric=`` / ``dissimilarity=`` before)."""
    from sklearn.manifold import MDS

    params = inspect.signature(MDS).parameters
    kw = {"n_components": dim, "random_state": seed, "max_iter": max_iter, "n_init": 1}
    if "metric_mds" in params:
        kw.update(metric_mds=metric, metric="precomputed")
        if "init" in params:
            kw["init"] = "random"
    else:  # pragma: no cover - scikit-learn < 1.8
        kw.update(metric=metric, dissimilarity="precomputed")
    if "normalized_stress" in params:
        kw["normalized_stress"] = "auto" if not metric else False
    return MDS(**kw)


def nonmetric_mds(verts, faces, dim: int = 3, seed: int = 0, max_iter: int = 300, D: np.ndarray | None = None) -> np.ndarray:
    """Non-metric MDS (keeps the order of the geodesic distances), started from classical MDS."""
    D = geodesic_matrix(verts, faces) if D is None else D
    est = _mds_estimator(dim, seed, max_iter, metric=False)
    return est.fit_transform(D, init=classical_mds(verts, faces, dim, D=D))


def smacof_mds(verts, faces, dim: int = 3, seed: int = 0, max_iter: int = 300, D: np.ndarray | None = None,
               eps: float = 1e-6) -> np.ndarray:
    """Least-squares MDS (SMACOF) of the geodesic distances, started from classical MDS."""
    D = geodesic_matrix(verts, faces) if D is None else D
    from sklearn.manifold import smacof

    init = classical_mds(verts, faces, dim, D=D)
    kw = {"n_components": dim, "init": init, "n_init": 1, "max_iter": max_iter, "random_state": seed, "eps": eps}
    if "metric" in inspect.signature(smacof).parameters:
        kw["metric"] = True
    X, _ = smacof(D, **{k: v for k, v in kw.items() if k in inspect.signature(smacof).parameters})[:2]
    return X


def cotangent_laplacian(verts: np.ndarray, faces: np.ndarray) -> tuple[sp.csr_matrix, np.ndarray]:
    """Cotangent stiffness ``L`` (positive semi-definite) and lumped vertex areas ``M``."""
    n = len(verts)
    I, J, W = [], [], []
    area = np.zeros(n)
    for k in range(3):
        i, j, o = faces[:, k], faces[:, (k + 1) % 3], faces[:, (k + 2) % 3]
        u, v = verts[i] - verts[o], verts[j] - verts[o]
        cross = np.linalg.norm(np.cross(u, v), axis=1)
        cot = (u * v).sum(1) / np.maximum(cross, 1e-12)
        I += [i, j]; J += [j, i]; W += [0.5 * cot, 0.5 * cot]  # noqa: E702
    tri = verts[faces]
    fa = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    for k in range(3):
        np.add.at(area, faces[:, k], fa / 3)
    Wm = sp.coo_matrix((np.concatenate(W), (np.concatenate(I), np.concatenate(J))), shape=(n, n)).tocsr()
    L = sp.diags(np.asarray(Wm.sum(1)).ravel()) - Wm
    return L.tocsr(), np.maximum(area, 1e-12)


def gps_embedding(verts, faces, dim: int = 3) -> np.ndarray:
    """GPS (Rustamov 2007): phi_i / sqrt(lambda_i) for the ``dim`` smallest non-zero eigenpairs of
    L phi = lambda M phi (cotangent Laplacian, lumped mass)."""
    L, area = cotangent_laplacian(verts, faces)
    M = sp.diags(area)
    k = min(dim + 1, len(verts) - 2)
    v0 = np.random.default_rng(0).standard_normal(L.shape[0])  # ARPACK's own start vector is random
    vals, vecs = eigsh(L + 1e-8 * M, k=k, M=M, sigma=-1e-6, which="LM", v0=v0)
    # fix each eigenvector's sign (largest-magnitude entry positive): same embedding on every run
    vecs = vecs * np.sign(vecs[np.abs(vecs).argmax(0), np.arange(vecs.shape[1])])
    order = np.argsort(vals)[1:dim + 1]
    return vecs[:, order] / np.sqrt(np.maximum(vals[order], 1e-12))


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
        v, f = simplify(np.asarray(v, float), np.asarray(f, np.int64), max_vertices)
        D = geodesic_matrix(v, f) if needs_geo else None
        for m in methods:
            out[m].append((canonical_form(v, f, m, D=D, max_iter=max_iter, eps=eps), f))
    return out


def baseline_retrieval(meshes, labels, methods, cfg=None, max_vertices: int = 1000, max_iter: int = 300,
                       eps: float = 1e-4) -> dict[str, dict]:
    """Retrieval scores of non-learned canonical forms: each mesh ``(verts, faces)`` -> its canonical
    form by every method -> the view-based descriptor (:mod:`lit3d.retrieval.descriptor`, config
    ``cfg``) -> distance matrix -> :func:`lit3d.metrics.retrieval.retrieval_scores` with ``labels``
    ``(n,)``. Returns ``{method: {"nn", "ft", "st", "e", "dcg", "seconds"}}``."""
    import time

    from lit3d.metrics.retrieval import retrieval_scores
    from lit3d.retrieval.descriptor import DescriptorConfig, distance_matrix_from_meshes

    cfg = cfg or DescriptorConfig()
    labels = np.asarray(labels)
    t0 = time.perf_counter()
    forms = canonical_forms_multi(meshes, methods, max_vertices, max_iter, eps)
    t_forms = (time.perf_counter() - t0) / max(len(list(methods)), 1)
    out = {}
    for m, fm in forms.items():
        t1 = time.perf_counter()
        scores = dict(retrieval_scores(distance_matrix_from_meshes(fm, cfg), labels))
        scores["seconds"] = t_forms + time.perf_counter() - t1
        out[m] = scores
    return out
