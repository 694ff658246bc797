"""Spectral embeddings of triangle meshes.

    L, area = cotangent_laplacian(verts, faces)   # (V, V) PSD stiffness, (V,) lumped areas
    X = gps_embedding(verts, faces)               # (V, 3) Global Point Signature
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
