"""Multidimensional scaling of a geodesic distance matrix (canonical-form baselines).

    classical_mds(verts, faces)   classical (Torgerson) MDS -> (V, dim)
    smacof_mds(verts, faces)      least-squares MDS (SMACOF, scikit-learn) -> (V, dim)
    nonmetric_mds(verts, faces)   non-metric MDS (scikit-learn, 1.8 argument names shimmed) -> (V, dim)

    landmark_mds(D_lv, idx)       landmark MDS (de Silva & Tenenbaum 2004) -> (V, dim)
    landmark_smacof(D_lv, idx)    SMACOF of the landmarks, other vertices placed by triangulation

Each of the first three takes a precomputed ``(V, V)`` matrix ``D`` or computes it with
:func:`lit3d.geometry.geodesics.geodesic_matrix`; the landmark ones take the ``(L, V)`` rows of
:func:`lit3d.geometry.geodesics.landmark_geodesics` (full-resolution meshes).
"""
from __future__ import annotations

import inspect

import numpy as np

from lit3d.geometry.geodesics import geodesic_matrix


def classical_mds(verts, faces, dim: int = 3, D: np.ndarray | None = None) -> np.ndarray:
    """Torgerson MDS: double-centred squared geodesics, top eigenvectors scaled by sqrt(eigenvalue)."""
    D = geodesic_matrix(verts, faces) if D is None else D
    return classical_mds_of(D, dim)


def classical_mds_of(D: np.ndarray, dim: int = 3) -> np.ndarray:
    """Torgerson MDS of a symmetric ``(n, n)`` distance matrix -> ``(n, dim)`` float64."""
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


def triangulate(Y: np.ndarray, D2: np.ndarray) -> np.ndarray:
    """Place points from their squared distances ``D2`` ``(L, N)`` to landmarks embedded at ``Y``
    ``(L, dim)``: the least-squares solution of ``|x - y_i|^2 = D2[i]`` after removing the mean over
    landmarks (de Silva & Tenenbaum's landmark-MDS step when ``Y`` is a classical-MDS embedding).
    Returns ``(N, dim)`` float64."""
    mu = Y.mean(0)
    Yc = Y - mu
    rhs = D2 - (Yc ** 2).sum(1)[:, None]
    rhs = rhs - rhs.mean(0)
    return (-0.5 * np.linalg.pinv(Yc) @ rhs).T + mu


def _landmark_matrix(D_lv: np.ndarray, idx: np.ndarray) -> np.ndarray:
    Dl = D_lv[:, idx]
    return (Dl + Dl.T) / 2


def landmark_mds(D_lv: np.ndarray, idx: np.ndarray, dim: int = 3) -> np.ndarray:
    """Landmark MDS: classical MDS of the ``(L, L)`` landmark geodesics, every vertex triangulated
    from its distances to the landmarks. ``D_lv`` ``(L, V)``, ``idx`` ``(L,)`` -> ``(V, dim)``; equal
    to :func:`classical_mds` when every vertex is a landmark."""
    return triangulate(classical_mds_of(_landmark_matrix(D_lv, idx), dim), D_lv ** 2)


def landmark_smacof(D_lv: np.ndarray, idx: np.ndarray, dim: int = 3, seed: int = 0, max_iter: int = 300,
                    eps: float = 1e-6) -> np.ndarray:
    """SMACOF of the landmark geodesics (started from their classical MDS), every vertex
    triangulated from its distances to the landmarks. ``(L, V)``, ``(L,)`` -> ``(V, dim)``."""
    Dl = _landmark_matrix(D_lv, idx)
    Y = smacof_mds(None, None, dim, seed, max_iter, D=Dl, eps=eps)
    return triangulate(Y, D_lv ** 2)


def landmark_nmds(D_lv: np.ndarray, idx: np.ndarray, dim: int = 3, seed: int = 0, max_iter: int = 300) -> np.ndarray:
    """Non-metric MDS of the landmark geodesics (its embedding rescaled to fit the geodesics in least
    squares, since non-metric MDS keeps only their order), every vertex triangulated as above."""
    from scipy.spatial.distance import pdist, squareform

    Dl = _landmark_matrix(D_lv, idx)
    Y = nonmetric_mds(None, None, dim, seed, max_iter, D=Dl)
    dy = squareform(pdist(Y))
    Y = Y * (dy * Dl).sum() / max((dy ** 2).sum(), 1e-12)
    return triangulate(Y, D_lv ** 2)
