"""PointSSIM: structural similarity of two point clouds (Alexiou & Ebrahimi, ICMEW 2020).

PointSSIM compares *local structure* rather than point-to-point errors. For each cloud
separately, every point's neighbourhood (its ``k`` nearest points, itself included) gives a
set of attribute quantities; a statistical estimator (by default the variance) turns each
set into one feature value per point (a feature map). The two feature maps are associated
through nearest neighbours, compared by their relative difference, and pooled:

- association: each point of ``B`` takes the feature of its nearest point of ``A``
  (``A`` as reference, score of ``B``), and each point of ``A`` that of its nearest point
  of ``B`` (``B`` as reference, score of ``A``);
- error map: ``e = |f_ref - f| / (max(|f_ref|, |f|) + eps)``, ``eps = 2.22e-16`` (MATLAB ``eps(1)``);
- similarity map ``1 - e``, pooled (default: mean, ignoring NaN); with no reference fixed
  (the only mode here) the symmetric score is the *minimum* of the two directions.

Quantities per neighbourhood (``idx``: the ``(N, k)`` neighbour indices, column 0 the point):

- geometry: distances to the ``k - 1`` other neighbours;
- normal: ``1 - 2 arccos(|n_i . n_j| / (|n_i| |n_j|)) / pi`` between the point's normal and
  each of its ``k - 1`` other neighbours' normals;
- curvature: the curvature of all ``k`` neighbourhood points (self included);
- colour: the luminance of all ``k`` neighbourhood points (self included): ITU-R BT.709
  ``Y = 0.2126 R + 0.7152 G + 0.0722 B`` on 8-bit RGB, rounded to an 8-bit integer.

Reference: EPFL MMSPG's MATLAB code, https://github.com/mmspg/pointssim
(``structural_similarity/pointssim.m``, ``feature_map.m``, ``error_map.m``, ``ssim_score.m``,
``pooling.m``, ``rgb_to_yuv.m``). Its defaults, followed here: neighbourhood of 12 points
(``knnsearch(A, A, 'K', 12)``, the point itself included), estimator ``'VAR'`` (MATLAB
``var(q, [], 2)``: the *sample* variance, ``N - 1``), pooling ``'Mean'`` (``nanmean``),
``CONST = eps(1)``, ``REF = 0`` (symmetric: ``min`` of the two directions' scores).
Estimators offered here: ``"variance"`` (``'VAR'``), ``"std"`` (``'STD'``, sample),
``"mean_ad"`` (``'MeanAD'``), ``"median_ad"`` (``'MedianAD'``), ``"cov"`` (``'COV'``, std / mean),
``"mean"`` (``'Mean'``) and ``"median"`` (not in the reference). Pooling: ``"mean"``,
``"mse"`` and ``"rms"`` (``'Mean'``, ``'MSE'``, ``'RMSE'``), applied, as in the reference, to
the *similarity* map ``1 - e`` (``"mse"`` is ``mean((1 - e)^2)``); with ``"mean"`` this is
``1 - mean(e)``.

Shapes: ``points_a (N, 3)``, ``points_b (M, 3)`` float positions in one frame; colours
``(N, 3)``/``(M, 3)`` RGB in ``[0, 1]``; normals ``(N, 3)``/``(M, 3)`` (any length, any sign).
Internally: neighbour indices/distances ``(N, k)``, quantities ``(N, k)`` or ``(N, k - 1)``,
feature maps ``(N,)``. All quantities are non-negative, so every score is in ``[0, 1]``
(1: identical local structure); higher is better.

Cost: one KD-tree and one ``k``-NN self query per cloud, one 1-NN query each direction;
covariances and their smallest eigenvalue/eigenvector in closed form (no ``numpy.linalg`` per
point). Each cloud is processed in its KD-tree's leaf order (queries and gathers then stay in
cache: about 3x faster queries than a random point order; the pooled scores do not depend on
the order), and the two clouds run in two threads (SciPy queries and NumPy loops release the GIL).

Differences from the reference code:

- Normals: the reference takes given normals (its example estimates them by quadric fitting
  over a radius of 1% of the bounding box, ``pc_estimate_norm_curv_qfit.m``). Here, when no
  normals are given, they are the PCA normals (smallest covariance eigenvector) of the same
  ``k``-point neighbourhoods used for the metric.
- Curvature: the reference takes given curvatures (its example: mean curvature of the local
  quadric fit). Here it is always the PCA *surface variation*
  ``lambda_min / (lambda_1 + lambda_2 + lambda_3)`` of the ``k``-point neighbourhood (0 where
  all ``k`` points coincide), so the curvature score is not numerically the reference's.
- Colour: inputs in ``[0, 1]`` are scaled by 255 before the BT.709 luma; the luma is rounded
  half away from zero and clipped to ``[0, 255]`` like MATLAB's ``uint8(round(y))``. Only
  luminance is used, as in the reference; a uniform luminance offset does not change the
  variance, so it leaves the default colour score at 1 (it is structural, not a colour error).
- Only the symmetric score (``REF = 0``) is returned; the estimator ``'QCD'`` is not offered.
- The reference sorts points (``sortrows``) before searching and its example fuses duplicate
  points first; here points are only reordered (KD-tree leaf order) and not fused. This only
  changes which neighbour is taken among equidistant ones (ties, e.g. duplicate points, where
  column 0 may be a duplicate rather than the point itself, as in the reference), where
  SciPy's and MATLAB's choices differ, and the summation order of the pooled mean (~1e-16).
- ``k`` is clamped to the size of the smaller cloud (the reference fails instead).
"""
from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from lit3d.metrics.pointcloud import checked_tree, kd_tree
from lit3d.render.point_clouds import smallest_eigenvalue, smallest_eigenvector

EPS = float(np.finfo(np.float64).eps)  # the reference's CONST = eps(1)
Y709 = np.array([0.2126, 0.7152, 0.0722])

ESTIMATORS: dict[str, Callable[[np.ndarray], np.ndarray]] = {
    "variance": lambda q: q.var(1, ddof=1),
    "std": lambda q: q.std(1, ddof=1),
    "mean_ad": lambda q: np.abs(q - q.mean(1, keepdims=True)).mean(1),
    "median_ad": lambda q: np.median(np.abs(q - np.median(q, 1, keepdims=True)), 1),
    "cov": lambda q: q.std(1, ddof=1) / q.mean(1),
    "mean": lambda q: q.mean(1),
    "median": lambda q: np.median(q, 1),
}
POOLINGS: dict[str, Callable[[np.ndarray], float]] = {
    "mean": lambda s: float(np.nanmean(s)),
    "mse": lambda s: float(np.nanmean(s * s)),
    "rms": lambda s: float(np.sqrt(np.nanmean(s * s))),
}


def luma8(colours: np.ndarray) -> np.ndarray:
    """BT.709 luma ``(N,) float64`` of RGB ``(N, 3)`` in ``[0, 1]``, as the reference's 8-bit ``uint8(round(Y))``."""
    y = np.asarray(colours, dtype=np.float64)[:, :3] @ (255.0 * Y709)
    return np.clip(np.floor(y + 0.5), 0.0, 255.0)  # round half up (= MATLAB's away from zero for y >= 0), saturate


def _covariance(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Scatter matrices ``(N, 3, 3) float64`` of neighbourhoods given as ``(N, k)`` coordinate columns.

    :func:`lit3d.render.point_clouds.neighbour_covariance` written for separate columns, which are
    cheaper to gather than ``(N, k, 3)`` rows.
    """
    k = x.shape[1]
    cols = (x, y, z)
    m = [c.mean(1) for c in cols]
    c = np.empty((len(x), 3, 3), dtype=np.float64)
    for i in range(3):
        for j in range(i, 3):
            c[:, i, j] = c[:, j, i] = np.einsum("nk,nk->n", cols[i], cols[j]) - k * m[i] * m[j]
    return c


class _Cloud:
    """One cloud in its KD-tree's leaf order (spatially coherent: neighbour queries and gathers stay in cache).

    Attributes (all in that order): ``order (N,)`` the permutation from the input order,
    ``tree`` (over the input order), ``inverse (N,)`` input index -> sorted index, ``points (N, 3)``,
    ``dist``/``idx (N, k)`` the ``k`` nearest neighbours (column 0: the point itself).
    """

    def __init__(self, points: np.ndarray, k: int, workers: int, tree=None):
        self.tree = kd_tree(points) if tree is None else tree  # sliding midpoint: builds faster, queries as fast
        self.order = self.tree.indices
        self.inverse = np.empty_like(self.order)
        self.inverse[self.order] = np.arange(len(self.order))
        self.points = points[self.order]
        self.dist, idx = self.tree.query(self.points, k=k, workers=workers)
        self.idx = self.inverse[idx]
        self.workers = workers

    def nearest_in(self, other: _Cloud) -> np.ndarray:
        """``(N,)`` index (in ``other``'s order) of the nearest point of ``other`` to each of this cloud's points."""
        return other.inverse[other.tree.query(self.points, k=1, workers=self.workers)[1]]

    def quantities(self, colours: np.ndarray | None, normals: np.ndarray | None) -> dict[str, np.ndarray]:
        """Per-variant neighbourhood quantities ``(N, k - 1)`` (geometry, normal) or ``(N, k)`` (curvature, colour)."""
        idx = self.idx
        cols = [np.ascontiguousarray(self.points[:, c]) for c in range(3)]
        cov = _covariance(*(c[idx] - c[:, None] for c in cols))  # offsets from the centre point: well conditioned
        trace = cov[:, 0, 0] + cov[:, 1, 1] + cov[:, 2, 2]
        lam = np.maximum(smallest_eigenvalue(cov), 0.0)
        curv = np.divide(lam, trace, out=np.zeros_like(trace), where=trace > 0)
        n = smallest_eigenvector(cov) if normals is None else np.asarray(normals)[self.order]
        n = n.astype(np.float64)
        with np.errstate(invalid="ignore", divide="ignore"):  # zero-length normals give NaN, as in the reference
            n /= np.linalg.norm(n, axis=1, keepdims=True)
            nb = idx[:, 1:]
            cos = np.zeros(nb.shape)
            for c in range(3):
                nc = np.ascontiguousarray(n[:, c])
                cos += nc[nb] * nc[:, None]
            cos = np.abs(cos)
        quant = {
            "geometry": self.dist[:, 1:],
            "normal": 1.0 - 2.0 * np.arccos(np.minimum(cos, 1.0)) / np.pi,
            "curvature": curv[idx],
        }
        if colours is not None:
            quant["colour"] = luma8(colours)[self.order][idx]
        return quant


def pointssim(points_a, points_b, colours_a=None, colours_b=None, *, normals_a=None, normals_b=None,
              k: int = 12, estimator: str = "variance", pooling: str = "mean", workers: int = -1,
              trees=None) -> dict[str, float]:
    """Symmetric PointSSIM scores of two point clouds, one per attribute (1: identical, higher is better).

    Args:
        points_a: ``(N, 3)`` float positions of cloud A.
        points_b: ``(M, 3)`` float positions of cloud B, in A's frame.
        colours_a: ``(N, 3)`` RGB in ``[0, 1]`` or None.
        colours_b: ``(M, 3)`` RGB in ``[0, 1]`` or None; the colour score needs both.
        normals_a: ``(N, 3)`` normals or None (then PCA normals of the ``k`` neighbours).
        normals_b: ``(M, 3)`` normals or None.
        k: neighbourhood size, the point itself included (reference: 12).
        estimator: feature estimator, one of :data:`ESTIMATORS` (reference: ``"variance"``).
        pooling: pooling of the similarity map, one of :data:`POOLINGS` (reference: ``"mean"``).
        workers: SciPy KD-tree query threads (-1: all cores); with 1 the two clouds are also
            processed one after the other instead of in two threads.
        trees: ``(tree_a, tree_b)``, the clouds' :func:`lit3d.metrics.pointcloud.kd_tree` if already built
            (e.g. for :func:`lit3d.metrics.pcqm.pcqm` too; the same scores as without), or None.

    Returns:
        ``{"pointssim_geometry", "pointssim_normal", "pointssim_curvature"}`` and, when both
        clouds have colours, ``"pointssim_colour"``: each the minimum over the two directions.
    """
    if estimator not in ESTIMATORS:
        raise ValueError(f"estimator must be one of {sorted(ESTIMATORS)}, got {estimator!r}")
    if pooling not in POOLINGS:
        raise ValueError(f"pooling must be one of {sorted(POOLINGS)}, got {pooling!r}")
    a = np.asarray(points_a, dtype=np.float64)
    b = np.asarray(points_b, dtype=np.float64)
    for label, p, extras in (("a", a, (colours_a, normals_a)), ("b", b, (colours_b, normals_b))):
        if p.ndim != 2 or p.shape[1] != 3 or not np.isfinite(p).all():
            raise ValueError(f"points_{label} must be a finite (N, 3) array, got shape {p.shape}")
        for what, x in zip(("colours", "normals"), extras):
            if x is not None and np.shape(x) != p.shape:
                raise ValueError(f"{what}_{label} must have the shape of points_{label} {p.shape}, got {np.shape(x)}")
    k = min(int(k), len(a), len(b))
    if k < 3:
        raise ValueError(f"PointSSIM needs neighbourhoods of at least 3 points: k={k}, clouds of {len(a)} and {len(b)}")
    with_colour = colours_a is not None and colours_b is not None
    feature, pool = ESTIMATORS[estimator], POOLINGS[pooling]
    tree_a, tree_b = (None, None) if trees is None else (checked_tree(trees[0], a, "points_a"),
                                                         checked_tree(trees[1], b, "points_b"))

    def features(points, colours, normals, tree) -> tuple[_Cloud, dict[str, np.ndarray]]:
        cloud = _Cloud(points, k, workers, tree)
        with np.errstate(invalid="ignore", divide="ignore"):
            return cloud, {name: feature(q) for name, q in cloud.quantities(colours, normals).items()}

    # The two clouds in two threads: KD-tree queries and most NumPy loops release the GIL.
    jobs = [(a, colours_a if with_colour else None, normals_a, tree_a),
            (b, colours_b if with_colour else None, normals_b, tree_b)]
    if workers == 1:
        (cloud_a, feat_a), (cloud_b, feat_b) = (features(*job) for job in jobs)
    else:
        with ThreadPoolExecutor(2) as pool_ex:
            (cloud_a, feat_a), (cloud_b, feat_b) = pool_ex.map(lambda job: features(*job), jobs)
    id_ba = cloud_b.nearest_in(cloud_a)  # nearest point of A for each point of B (A as reference)
    id_ab = cloud_a.nearest_in(cloud_b)  # nearest point of B for each point of A (B as reference)
    out = {}
    with np.errstate(invalid="ignore", divide="ignore"):
        for name in feat_a:
            fa, fb = feat_a[name], feat_b[name]
            scores = []
            for f, f_ref in ((fb, fa[id_ba]), (fa, fb[id_ab])):
                err = np.abs(f_ref - f) / (np.maximum(np.abs(f_ref), np.abs(f)) + EPS)
                scores.append(pool(1.0 - err))
            out[f"pointssim_{name}"] = float(np.fmin(*scores))  # MATLAB's min: NaN-ignoring
    return out
