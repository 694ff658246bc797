"""Spectral embeddings of triangle meshes.

    L, area = cotangent_laplacian(verts, faces)   # (V, V) PSD stiffness, (V,) lumped areas
    X = gps_embedding(verts, faces)               # (V, 3) Global Point Signature
    dna = shape_dna(verts, faces, k=30)           # (30,) area-normalised eigenvalues (ShapeDNA)
    D = shape_dna_distances(np.stack(dnas))       # (n, n)
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import eigsh


def cotangent_laplacian(verts: np.ndarray, faces: np.ndarray) -> tuple[sp.csr_matrix, np.ndarray]:
    """Cotangent stiffness and lumped (barycentric) vertex areas, from potpourri3d.

    Args:
        verts: ``(V, 3)`` float vertex positions.
        faces: ``(F, 3)`` int triangle indices.

    Returns:
        ``L`` ``(V, V)`` float64 CSR, positive semi-definite (``L[i, j] = -(cot a + cot b) / 2``
        for an edge ``ij``, rows summing to 0), and ``area`` ``(V,)`` float64: a third of the
        area of each incident face, at least 1e-12.
    """
    import potpourri3d as pp3d

    v = np.asarray(verts, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    L = pp3d.cotan_laplacian(v, f, denom_eps=1e-12)
    return sp.csr_matrix(L), np.maximum(pp3d.vertex_areas(v, f), 1e-12)


def _smallest_eigenpairs(L: sp.csr_matrix, area: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """The ``k`` smallest eigenpairs of L phi = lambda M phi (M = diag(area)), ascending, each
    eigenvector's sign fixed (largest-magnitude entry positive), so runs agree."""
    M = sp.diags(area)
    k = min(k, L.shape[0] - 2)
    v0 = np.random.default_rng(0).standard_normal(L.shape[0])  # ARPACK's own start vector is random
    vals, vecs = eigsh(L + 1e-8 * M, k=k, M=M, sigma=-1e-6, which="LM", v0=v0)
    order = np.argsort(vals)
    vals, vecs = vals[order], vecs[:, order]
    return vals, vecs * np.sign(vecs[np.abs(vecs).argmax(0), np.arange(vecs.shape[1])])


def shape_dna(verts, faces, k: int = 30, normalise: bool = True) -> np.ndarray:
    """ShapeDNA (Reuter et al. 2006): the first ``k`` non-zero eigenvalues ``(k,)`` float64 of the
    cotangent Laplace-Beltrami operator (lumped mass), multiplied by the surface area when
    ``normalise`` (scale invariance: eigenvalues scale as 1 / length^2). Intrinsic, so unchanged by
    isometric bending: a pose-invariant descriptor of the full mesh. The first eigenvalue (0 for a
    connected mesh) is dropped."""
    L, area = cotangent_laplacian(verts, faces)
    vals, _ = _smallest_eigenpairs(L, area, k + 1)
    vals = vals[1:k + 1]
    return vals * area.sum() if normalise else vals


def shape_dna_distances(dnas: np.ndarray) -> np.ndarray:
    """``(n, n)`` Euclidean distances between ShapeDNA vectors ``(n, k)``, each eigenvalue divided by
    its Weyl-law growth ``4 pi i`` (i = 1..k) so that every eigenvalue weighs about the same."""
    from scipy.spatial.distance import cdist

    dnas = np.asarray(dnas, np.float64)
    w = dnas / (4 * np.pi * np.arange(1, dnas.shape[1] + 1))
    return cdist(w, w)


def gps_embedding(verts, faces, dim: int = 3) -> np.ndarray:
    """GPS (Rustamov 2007): phi_i / sqrt(lambda_i) for the ``dim`` smallest non-zero eigenpairs of
    L phi = lambda M phi (cotangent Laplacian, lumped mass)."""
    L, area = cotangent_laplacian(verts, faces)
    vals, vecs = _smallest_eigenpairs(L, area, dim + 1)
    return vecs[:, 1:dim + 1] / np.sqrt(np.maximum(vals[1:dim + 1], 1e-12))
