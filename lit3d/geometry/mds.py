"""Multidimensional scaling of a geodesic distance matrix (canonical-form baselines).

    classical_mds(verts, faces)   classical (Torgerson) MDS -> (V, dim)
    smacof_mds(verts, faces)      least-squares MDS (SMACOF, scikit-learn) -> (V, dim)
    nonmetric_mds(verts, faces)   non-metric MDS (scikit-learn, 1.8 argument names shimmed) -> (V, dim)

Each takes a precomputed ``(V, V)`` matrix ``D`` or computes it with
:func:`lit3d.geometry.geodesics.geodesic_matrix`.
"""
from __future__ import annotations

import inspect

import numpy as np

from lit3d.geometry.geodesics import geodesic_matrix


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
