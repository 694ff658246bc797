"""Standard point-cloud quality baselines (MPEG pc_error definitions) from SciPy KD-trees.

For a reference ``A`` and a distorted cloud ``B`` (``(N, 3)`` positions in one frame):

- D1 (point-to-point): ``e_B->A = mean_b ||b - a_nn(b)||^2``; symmetric ``MSE = max(e_A->B, e_B->A)``;
- D2 (point-to-plane): the same with the error projected on the neighbour's unit normal,
  ``((b - a_nn(b)) . n_a)^2`` (normals of ``A`` for ``B->A``, of ``B`` for ``A->B``);
- PSNR: ``10 log10(peak^2 / MSE)`` with ``peak`` the reference's bounding-box diagonal
  (pc_error takes the voxel grid's peak value; any fixed peak gives the same ranking),
  capped at ``PSNR_MAX_DB`` for identical geometry;
- colour (Y) PSNR: BT.709 luma (as pc_error) of each point against its nearest neighbour's,
  colours in ``[0, 1]`` (peak 1), symmetric as D1 (the worse direction);
- Hausdorff: ``max(max_b ||b - a_nn||, max_a ||a - b_nn||)``; Chamfer: mean of the two
  directed mean distances (the mesh measures' definitions, :mod:`lit3d.metrics.mesh`).
"""
from __future__ import annotations

import numpy as np

from lit3d.metrics.image.pixel import PSNR_MAX_DB

Y709 = np.array([0.2126, 0.7152, 0.0722])


def nearest(src: np.ndarray, dst: np.ndarray, tree=None, workers: int = -1) -> tuple[np.ndarray, np.ndarray]:
    """``(distance (len(src),) float64, index (len(src),) int64)`` of each ``src`` point's nearest ``dst`` point."""
    from scipy.spatial import cKDTree

    tree = cKDTree(dst) if tree is None else tree
    d, i = tree.query(np.asarray(src, dtype=np.float64), k=1, workers=workers)
    return d, i


def kd_tree(points: np.ndarray):
    """The KD-tree :mod:`lit3d.metrics.pointssim` and :mod:`lit3d.metrics.pcqm` search ``(N, 3)`` float64
    ``points`` with: SciPy's ``cKDTree`` with sliding-midpoint splits (``balanced_tree=False``: builds
    faster, queries as fast). One tree per cloud can serve both metrics (their ``trees`` argument):
    the same tree answers a query exactly as a tree they build themselves (ties included)."""
    from scipy.spatial import cKDTree

    return cKDTree(points, balanced_tree=False)


def checked_tree(tree, points: np.ndarray, label: str):
    """``tree`` if it is a :func:`kd_tree` of exactly ``points`` (same count and coordinates), else ValueError."""
    data = getattr(tree, "data", None)
    if data is None or data.shape != points.shape or not np.array_equal(data, points):
        raise ValueError(f"the KD-tree given for {label} is not a tree of those points "
                         f"({getattr(data, 'shape', None)} vs {points.shape})")
    return tree


def psnr_db(mse: float, peak: float) -> float:
    """``10 log10(peak^2 / mse)`` in dB, capped at ``PSNR_MAX_DB``."""
    if mse <= 0:
        return PSNR_MAX_DB
    return float(min(10.0 * np.log10(peak * peak / mse), PSNR_MAX_DB))


def pointcloud_baselines(a: np.ndarray, b: np.ndarray, normals_a: np.ndarray | None = None,
                         normals_b: np.ndarray | None = None, colours_a: np.ndarray | None = None,
                         colours_b: np.ndarray | None = None, workers: int = -1) -> dict[str, float]:
    """Every baseline of the module doc for reference ``a`` and distorted ``b``.

    Args:
        a, b: ``(N, 3)`` / ``(M, 3)`` float positions in one frame.
        normals_a, normals_b: unit normals ``(N, 3)`` / ``(M, 3)`` (for D2; omitted -> no D2).
        colours_a, colours_b: RGB ``(N, 3)`` / ``(M, 3)`` in ``[0, 1]`` (omitted -> no Y PSNR).

    Returns:
        ``{"d1_mse", "d1_psnr", "d2_mse", "d2_psnr", "y_mse", "y_psnr", "hausdorff", "chamfer"}``
        (floats; D2/Y only when their inputs are given).
    """
    from scipy.spatial import cKDTree

    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    d_ba, i_ba = nearest(b, a, cKDTree(a), workers)  # each b -> nearest a
    d_ab, i_ab = nearest(a, b, cKDTree(b), workers)
    peak = float(np.linalg.norm(a.max(0) - a.min(0)))
    d1 = max(float(np.mean(d_ba ** 2)), float(np.mean(d_ab ** 2)))
    out = {"d1_mse": d1, "d1_psnr": psnr_db(d1, peak),
           "hausdorff": float(max(d_ba.max(), d_ab.max())), "chamfer": float(0.5 * (d_ba.mean() + d_ab.mean()))}
    if normals_a is not None and normals_b is not None:
        e_ba = np.einsum("ij,ij->i", b - a[i_ba], np.asarray(normals_a, np.float64)[i_ba]) ** 2
        e_ab = np.einsum("ij,ij->i", a - b[i_ab], np.asarray(normals_b, np.float64)[i_ab]) ** 2
        d2 = max(float(e_ba.mean()), float(e_ab.mean()))
        out.update(d2_mse=d2, d2_psnr=psnr_db(d2, peak))
    if colours_a is not None and colours_b is not None:
        ya = np.asarray(colours_a, np.float64) @ Y709
        yb = np.asarray(colours_b, np.float64) @ Y709
        y = max(float(np.mean((yb - ya[i_ba]) ** 2)), float(np.mean((ya - yb[i_ab]) ** 2)))
        out.update(y_mse=y, y_psnr=psnr_db(y, 1.0))
    return out
