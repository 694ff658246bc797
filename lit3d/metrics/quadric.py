"""Local quadric fits of point clouds for PCQM (:mod:`lit3d.metrics.pcqm`): each centre's neighbours in a PCA
frame, the least-squares height field ``z = a x^2 + b y^2 + c xy + d x + e y + f`` over the tangent plane, its
mean curvature at the centre and the centre's projection onto it (the reference code's
``computeProjectionAndCurvature``). Shapes: centres ``(E, 3)``, neighbour offsets ``(E, k, 3)``, masks ``(E, k)``.
"""
from __future__ import annotations

import numpy as np

from lit3d.render.point_clouds import smallest_eigenvector

K_PROJECTION = 20  # reference -knn: points of the projection fit (and most of the curvature fit)
K_MIN_CURVATURE = 6  # fewest points of a curvature fit (not in the reference)


def _refined_normal(cov: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Float64 unit eigenvectors ``(E, 3)`` of the smallest eigenvalues of ``cov (E, 3, 3)`` from approximations ``n``.

    :func:`lit3d.render.point_clouds.smallest_eigenvector` returns float32; one refinement in float64: the
    eigenvalue as the Rayleigh quotient of ``n`` (error quadratic in ``n``'s), the vector as the longest
    cross product of two rows of ``cov - lambda I`` (written out entry by entry), signed like ``n``
    (``n`` kept where all three are ~0: isotropic neighbourhoods).
    """
    a00, a01, a02, a11, a12, a22 = cov[:, 0, 0], cov[:, 0, 1], cov[:, 0, 2], cov[:, 1, 1], cov[:, 1, 2], cov[:, 2, 2]
    n0, n1, n2 = n[:, 0], n[:, 1], n[:, 2]
    lam = a00 * n0 * n0 + a11 * n1 * n1 + a22 * n2 * n2 + 2.0 * (a01 * n0 * n1 + a02 * n0 * n2 + a12 * n1 * n2)
    m00, m11, m22 = a00 - lam, a11 - lam, a22 - lam
    cands = (
        (a01 * a12 - a02 * m11, a02 * a01 - m00 * a12, m00 * m11 - a01 * a01),  # row 0 x row 1
        (a01 * m22 - a02 * a12, a02 * a02 - m00 * m22, m00 * a12 - a01 * a02),  # row 0 x row 2
        (m11 * m22 - a12 * a12, a12 * a02 - a01 * m22, a01 * a12 - m11 * a02),  # row 1 x row 2
    )
    best, best2 = np.zeros((len(n), 3)), np.zeros(len(n))
    for cand in cands:
        v2 = cand[0] ** 2 + cand[1] ** 2 + cand[2] ** 2
        take = v2 > best2
        best = np.where(take[:, None], np.stack(cand, 1), best)
        best2 = np.where(take, v2, best2)
    scale2 = np.maximum.reduce([np.abs(x) for x in (m00, m11, m22, a01, a02, a12)]) ** 2
    ok = best2 > 1e-18 * np.maximum(scale2, 1e-300) ** 2
    vec = np.where(ok[:, None], best, n)
    vec *= np.where((vec * n).sum(1) < 0, -1.0, 1.0)[:, None]
    return vec / np.linalg.norm(vec, axis=1, keepdims=True)


def _frame_coordinates(cols: list[np.ndarray], w: np.ndarray) -> tuple[np.ndarray, ...]:
    """Local PCA frame coordinates of neighbour offsets.

    Args:
        cols: the three ``(E, k)`` coordinate columns of the neighbour offsets from the origins.
        w: ``(E, k)`` 0/1 weights of the neighbours used.

    Returns:
        ``(x, y, z, n, scale)``: ``(E, k)`` coordinates divided by ``scale (E,)`` (the largest used
        offset length) along two tangents and the normal ``n (E, 3)`` (smallest eigenvector of the
        used neighbours' covariance; float64, unit length).
    """
    cnt = w.sum(1)
    wcols = [w * c for c in cols]
    mean = [wc.sum(1) / cnt for wc in wcols]
    cov = np.empty((len(w), 3, 3))
    for i in range(3):
        for j in range(i, 3):
            cov[:, i, j] = cov[:, j, i] = np.einsum("ek,ek->e", wcols[i], cols[j]) / cnt - mean[i] * mean[j]
    n = _refined_normal(cov, smallest_eigenvector(cov).astype(np.float64))
    t1 = np.cross(n, np.eye(3)[np.abs(n).argmin(1)])
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(n, t1)
    scale = np.sqrt(np.max((wcols[0] * cols[0] + wcols[1] * cols[1] + wcols[2] * cols[2]), axis=1))
    scale = np.where(scale > 0, scale, 1.0)
    x, y, z = (sum(cols[i] * (t[:, i] / scale)[:, None] for i in range(3)) for t in (t1, t2, n))
    return x, y, z, n, scale


# the six quadric monomials x^a y^b: x^2, y^2, xy, x, y, 1
_MONOMIALS = ((2, 0), (0, 2), (1, 1), (1, 0), (0, 1), (0, 0))


def _solve_spd(g: np.ndarray, h: np.ndarray, ridge: np.ndarray) -> np.ndarray:
    """Solutions ``(E, n)`` of the symmetric positive semi-definite systems ``(g + ridge I) x = h``.

    An ``L D L^T`` factorisation written over the batch (``n`` is 6: a few dozen array operations,
    several times faster than ``numpy.linalg.solve`` on tens of thousands of tiny matrices); pivots are
    floored at ``ridge`` so rank-deficient systems stay finite.
    """
    n = g.shape[1]
    low = np.zeros_like(g)
    d = np.empty(h.shape)
    for j in range(n):
        d[:, j] = np.maximum(g[:, j, j] + ridge - (low[:, j, :j] ** 2 * d[:, :j]).sum(1), ridge)
        for i in range(j + 1, n):
            low[:, i, j] = (g[:, i, j] - (low[:, i, :j] * low[:, j, :j] * d[:, :j]).sum(1)) / d[:, j]
    x = h.copy()
    for i in range(n):
        x[:, i] -= (low[:, i, :i] * x[:, :i]).sum(1)
    x /= d
    for i in reversed(range(n)):
        x[:, i] -= (low[:, i + 1:, i] * x[:, i + 1:]).sum(1)
    return x


def _fit(origins: np.ndarray, cols: list[np.ndarray], mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`quadric_fit` on the three ``(E, k)`` offset columns ``cols``."""
    w = mask.astype(np.float64)
    x, y, z, n, scale = _frame_coordinates(cols, w)
    wx = [w]
    for _ in range(4):
        wx.append(wx[-1] * x)
    y2 = y * y
    py = [None, y, y2, y2 * y, y2 * y2]
    mom = {(p, q): (wx[p].sum(1) if q == 0 else np.einsum("ek,ek->e", wx[p], py[q]))
           for p in range(5) for q in range(5 - p)}
    g = np.stack([mom[(pi + pj, qi + qj)] for pi, qi in _MONOMIALS for pj, qj in _MONOMIALS], 1).reshape(-1, 6, 6)
    h = np.stack([np.einsum("ek,ek->e", wx[p], z if q == 0 else py[q] * z) for p, q in _MONOMIALS], 1)
    coef = _solve_spd(g, h, 1e-13 * np.trace(g, axis1=1, axis2=2) / 6.0)
    fxx, fyy, fxy = 2.0 * coef[:, 0] / scale, 2.0 * coef[:, 1] / scale, coef[:, 2] / scale
    fx, fy = coef[:, 3], coef[:, 4]
    curv = 0.5 * ((1 + fx * fx) * fyy + (1 + fy * fy) * fxx - 2 * fxy * fx * fy) / (1 + fx * fx + fy * fy) ** 1.5
    return curv, origins + (coef[:, 5] * scale)[:, None] * n


def quadric_fit(origins: np.ndarray, neighbours: np.ndarray, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean curvature and projection of each origin on a quadric fitted to its neighbours.

    Args:
        origins: ``(E, 3)`` points the local frames are centred on.
        neighbours: ``(E, k, 3)`` neighbour positions.
        mask: ``(E, k) bool``, the neighbours used by each fit (at least 6 per row).

    Returns:
        ``(H (E,), proj (E, 3))``: the signed mean curvature of the least-squares height function
        ``z = a x^2 + b y^2 + c xy + d x + e y + f`` at ``(0, 0)`` (frame: PCA of the used neighbours,
        ``z`` along the smallest eigenvector) and ``origin + f n``. The normal equations are
        assembled from the 15 weighted moments ``sum x^a y^b`` (``a + b <= 4``) and solved by
        :func:`_solve_spd` with a 1e-13 relative ridge (singular neighbourhoods, e.g. collinear points,
        stay finite).
    """
    return _fit(origins, [neighbours[..., i] - origins[:, i, None] for i in range(3)], mask)


def local_surface(tree, cloud_cols: list[np.ndarray], centres: np.ndarray, radius: float, project: bool):
    """Curvature (and projection) of ``centres`` on a cloud from one single-threaded KD-tree query.

    Args:
        tree: the cloud's ``cKDTree``; cloud_cols: its three coordinate columns ``(P,)``.

    Returns:
        ``(|H| (E,), nearest index (E,), nearest distance (E,), projection (E, 3) or None)``.
    """
    k = min(K_PROJECTION, tree.n)
    dist, idx = tree.query(centres, k=k)
    dist, idx = dist.reshape(len(centres), k), idx.reshape(len(centres), k)
    cols = [cloud_cols[i][idx] - centres[:, i, None] for i in range(3)]
    near = (dist <= radius) | (np.arange(k) < min(K_MIN_CURVATURE, k))
    curv, _ = _fit(centres, cols, near)
    proj = _fit(centres, cols, np.ones_like(near))[1] if project else None
    return np.abs(curv), idx[:, 0], dist[:, 0], proj
