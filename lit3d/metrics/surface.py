"""Surface metrics of shape completion: Chamfer-L1, F-score at distance thresholds and normal
consistency (the measures of Occupancy Networks, PCN and Tatarchenko et al. 2019), on
marching-cubes surfaces of occupancy grids.

For a prediction and a target in one grid frame:

1. a grid's surface is the marching-cubes mesh of its occupied voxels (``> 0.5``; scikit-image,
   iso level 0.5, as :func:`lit3d.render.convert.voxels_to_mesh`), in the **unit frame**: the grid is
   the cube ``[-0.5, 0.5]^3`` (side 1), voxel ``[i, j, k]`` centred at ``((i, j, k) + 0.5) / R - 0.5``
   with ``R`` the grid's largest side;
2. ``n`` points are sampled on each surface, uniformly by area, with one fixed seed (so identical
   shapes give identical samples and score perfectly), each with its face's unit normal;
3. nearest neighbours both ways (:func:`lit3d.metrics.pointcloud.nearest`, SciPy KD-trees, a target's
   tree built once) give ``d_pt`` (each predicted point to the target's samples) and ``d_tp`` (the
   reverse), and the formulas of :mod:`lit3d.metrics.clouds` (the point-cloud library; one
   implementation) give:

   - Chamfer-L1 = ``(mean d_pt + mean d_tp) / 2``, the mean of unsquared distances, the two directions
     averaged (Occupancy Networks' "L1"; ``convention="l1"``), in units of the grid side;
   - Chamfer-L2 = ``mean d_pt^2 + mean d_tp^2``, squared distances, the two directions summed
     (``convention="pytorch3d"``: ``pytorch3d.loss.chamfer_distance``'s defaults);
   - F-score@f = ``2 P R / (P + R)``, precision ``P = mean(d_pt <= tau)``, recall
     ``R = mean(d_tp <= tau)``, ``tau = f x`` the diagonal of the target surface's bounding box (of its
     mesh's vertices; ``threshold_mode="bbox_diagonal"``; not Tatarchenko et al.'s share of the
     volume side, which is ``tau = f`` in this frame);
   - normal consistency = mean over both directions of ``|n . n_nearest|`` (unoriented; 1 = parallel).

A prediction with no occupied voxel (or an empty mesh) has no surface: Chamfer-L1 = sqrt(3)
(the unit cube's diagonal, the largest distance in the grid; Chamfer-L2 = 2 x 3, that distance squared
in both directions), F-score 0, normal consistency 0,
and it is counted as ``empty``. A target without a surface is left out (nothing to compare with).
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
import torch
from scipy.spatial import cKDTree
from torchmetrics import Metric

from lit3d.metrics.clouds import (CHAMFER_CONVENTIONS, chamfer_from_distances, consistency_from_neighbours,
                                  precision_recall_fscore)
from lit3d.metrics.pointcloud import nearest

if TYPE_CHECKING:
    import trimesh

EMPTY_CHAMFER = float(np.sqrt(3.0))  # the unit cube's diagonal
# the Chamfer measures of surface_scores -> their convention in lit3d.metrics.clouds
CHAMFER_KEYS = {"chamfer_l1": "l1", "chamfer_l2": "pytorch3d"}


@dataclass
class SurfaceSample:
    """Points on one surface: ``points (n, 3) float64``, their unit face ``normals (n, 3) float64``
    and ``diagonal``, the length of the surface's bounding-box diagonal (of its used vertices).
    :meth:`tree` builds the points' KD-tree once (a target is compared with several predictions)."""

    points: np.ndarray
    normals: np.ndarray
    diagonal: float
    _tree: cKDTree | None = field(default=None, repr=False, compare=False)

    def tree(self) -> cKDTree:
        if self._tree is None:
            self._tree = cKDTree(self.points)
        return self._tree


def fscore_key(fraction: float) -> str:
    """Metric name of an F-score threshold given as a fraction of the diagonal: 0.01 -> ``fscore_1pct``."""
    return f"fscore_{round(100 * float(fraction), 6):g}pct"


def grid_surface(grid: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """Marching-cubes surface of a ``(D, H, W)`` occupancy grid (``> 0.5`` = occupied) in the unit
    frame of the module doc: ``(vertices (V, 3) float64, faces (F, 3) int64)``, or None when no
    voxel is occupied.

    scikit-image's marching cubes at level 0.5 on the occupied box padded by one empty voxel, as
    :func:`lit3d.render.convert.voxels_to_mesh` does, but on the box only and without its
    orientation pass (about 3x faster at 64^3; the measures here use unoriented normals).
    """
    from skimage import measure  # at first use: importing the CompletionTask stays light

    occ = np.asarray(grid) > 0.5
    if not occ.any():
        return None
    lo, hi = [], []
    for axis in range(3):
        used = np.flatnonzero(occ.any(axis=tuple(a for a in range(3) if a != axis)))
        lo.append(int(used[0]))
        hi.append(int(used[-1]) + 1)
    box = np.pad(occ[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]].astype(np.float32), 1)
    verts, faces, _, _ = measure.marching_cubes(box, level=0.5)
    side = float(max(occ.shape))
    verts = (verts.astype(np.float64) + (np.asarray(lo, np.float64) - 1.0) + 0.5) / side - 0.5
    return verts, faces.astype(np.int64)


def sample_triangles(vertices: np.ndarray, faces: np.ndarray, n: int, seed: int) -> SurfaceSample | None:
    """``n`` points drawn uniformly by area on triangles ``vertices (V, 3)``, ``faces (F, 3)`` with a
    generator seeded ``seed``, each with its face's unit normal; None when the area is 0."""
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    if len(f) == 0:
        return None
    tri = v[f]  # (F, 3, 3)
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    cross = np.cross(e1, e2)
    area2 = np.linalg.norm(cross, axis=1)
    cum = np.cumsum(area2)
    if not cum[-1] > 0:
        return None
    rng = np.random.default_rng(int(seed))
    pick = np.minimum(np.searchsorted(cum, rng.random(int(n)) * cum[-1], side="right"), len(f) - 1)
    u, w = rng.random((2, int(n)))
    out = u + w > 1  # reflect into the triangle
    u[out], w[out] = 1 - u[out], 1 - w[out]
    points = tri[pick, 0] + u[:, None] * e1[pick] + w[:, None] * e2[pick]
    corners = tri.reshape(-1, 3)  # the vertices the faces use
    return SurfaceSample(points, cross[pick] / area2[pick, None],
                         float(np.linalg.norm(corners.max(0) - corners.min(0))))


def sample_mesh(mesh: trimesh.Trimesh | None, n: int, seed: int) -> SurfaceSample | None:
    """:func:`sample_triangles` of a ``trimesh.Trimesh`` (None: no mesh)."""
    return None if mesh is None else sample_triangles(mesh.vertices, mesh.faces, n, seed)


def sample_grids(grids: torch.Tensor | np.ndarray, n: int, seed: int) -> list[SurfaceSample | None]:
    """Surface samples of a batch of grids ``(B, 1, D, H, W)`` or ``(B, D, H, W)`` (any dtype,
    ``> 0.5`` = occupied): one :class:`SurfaceSample` or None (empty grid) per grid."""
    g = grids.detach().cpu().numpy() if isinstance(grids, torch.Tensor) else np.asarray(grids)
    g = g.reshape(g.shape[0], *g.shape[-3:])
    out = []
    for x in g:
        surface = grid_surface(x)
        out.append(None if surface is None else sample_triangles(*surface, n, seed))
    return out


def fscores(d_pt: np.ndarray, d_tp: np.ndarray, tau: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(precision, recall, fscore)``, each ``(T,)``, at distance thresholds ``tau (T,)`` from the nearest
    distances ``d_pt`` (each predicted point to the target) and ``d_tp`` (the reverse); F 0 where P + R = 0
    (:func:`lit3d.metrics.clouds.precision_recall_fscore` on one cloud)."""
    out = precision_recall_fscore(torch.from_numpy(np.asarray(d_pt, np.float64))[None],
                                  torch.from_numpy(np.asarray(d_tp, np.float64))[None],
                                  torch.as_tensor(np.asarray(tau, np.float64)))
    return tuple(v[0].numpy() for v in out)


def surface_scores(pred: SurfaceSample | None, target: SurfaceSample, fractions: Sequence[float]) -> dict:
    """Chamfer-L1, F-scores and normal consistency of one prediction against its target (module doc).

    Returns ``{"chamfer_l1": float, "chamfer_l2": float, "fscore": (T,) float64, "precision": (T,),
    "recall": (T,), "normal_consistency": float, "empty": bool}`` with ``T = len(fractions)``.
    """
    t = len(fractions)
    if pred is None:
        zeros = np.zeros(t)
        return {"chamfer_l1": EMPTY_CHAMFER, "chamfer_l2": 2 * EMPTY_CHAMFER ** 2, "fscore": zeros,
                "precision": zeros, "recall": zeros, "normal_consistency": 0.0, "empty": True}
    # one thread per query: the queries are short, and thread start-up dominated on a busy 2-core machine
    d_pt, i_pt = nearest(pred.points, target.points, target.tree(), workers=1)
    d_tp, i_tp = nearest(target.points, pred.points, pred.tree(), workers=1)
    precision, recall, fscore = fscores(d_pt, d_tp, np.asarray(fractions, dtype=np.float64) * target.diagonal)
    chamfers = {key: float(chamfer_from_distances(torch.from_numpy(d_pt)[None], torch.from_numpy(d_tp)[None],
                                                  **CHAMFER_CONVENTIONS[convention]._asdict()))
                for key, convention in CHAMFER_KEYS.items()}
    consistency = consistency_from_neighbours(torch.from_numpy(pred.normals)[None], torch.from_numpy(target.normals)[None],
                                              torch.from_numpy(np.asarray(i_pt, np.int64))[None],
                                              torch.from_numpy(np.asarray(i_tp, np.int64))[None])
    return {**chamfers, "fscore": fscore, "precision": precision, "recall": recall,
            "normal_consistency": float(consistency), "empty": False}


class SurfaceMetrics(Metric):
    """Mean Chamfer-L1, F-score at each threshold and normal consistency, per category.

    Args:
        categories: category names; ``update``'s ``category`` indexes them.
        points: points sampled on each surface.
        fscore_at: F-score thresholds as fractions of the target's bounding-box diagonal.
        seed: sampling seed (the same for prediction and target).

    ``update(preds, target, category)``: ``preds`` and ``target`` are grids ``(B, 1, D, H, W)``
    (``> 0.5`` = occupied; threshold probabilities first) or lists of ``B``
    :class:`SurfaceSample` / None (already sampled, e.g. a target shared by several predictions,
    or meshes); ``category (B,)`` int64, out of range = ignored.
    ``compute()`` returns ``chamfer_l1`` (), ``fscore`` (T,), ``normal_consistency`` (), means over
    the scored samples; ``*_per_category`` (C,) / (C, T) (NaN where a category has no sample);
    ``count_per_category`` (C,) and ``empty_per_category`` (C,) (predictions without surface).
    States are sums and counts reduced with ``sum``, so the result is the same on any number of
    processes.
    """

    full_state_update = False

    def __init__(self, categories: Sequence[str], points: int, fscore_at: Sequence[float], seed: int = 0, **kwargs):
        super().__init__(**kwargs)
        if int(points) < 1 or not fscore_at or min(fscore_at) <= 0:
            raise ValueError(f"surface metrics: points={points} must be >= 1 and fscore_at={list(fscore_at)} "
                             "non-empty fractions > 0")
        self.categories = list(categories)
        self.points, self.seed = int(points), int(seed)
        self.fscore_at = [float(f) for f in fscore_at]
        c, t = len(self.categories), len(self.fscore_at)
        self.add_state("chamfer_sum", torch.zeros(c, dtype=torch.float64), dist_reduce_fx="sum")
        self.add_state("fscore_sum", torch.zeros(c, t, dtype=torch.float64), dist_reduce_fx="sum")
        self.add_state("normal_sum", torch.zeros(c, dtype=torch.float64), dist_reduce_fx="sum")
        self.add_state("count", torch.zeros(c, dtype=torch.float64), dist_reduce_fx="sum")
        self.add_state("empty", torch.zeros(c, dtype=torch.float64), dist_reduce_fx="sum")

    def samples(self, grids: torch.Tensor | np.ndarray) -> list[SurfaceSample | None]:
        """:func:`sample_grids` with this metric's point count and seed."""
        return sample_grids(grids, self.points, self.seed)

    def update(self, preds, target, category: torch.Tensor) -> None:
        pred_s = preds if isinstance(preds, (list, tuple)) else self.samples(preds)
        tgt_s = target if isinstance(target, (list, tuple)) else self.samples(target)
        cats = torch.as_tensor(category).long().tolist()
        if not len(pred_s) == len(tgt_s) == len(cats):
            raise ValueError(f"SurfaceMetrics.update: {len(pred_s)} predictions, {len(tgt_s)} targets, "
                             f"{len(cats)} categories")
        for p, y, c in zip(pred_s, tgt_s, cats):
            if y is None or not 0 <= c < len(self.categories):
                continue
            s = surface_scores(p, y, self.fscore_at)
            self.chamfer_sum[c] += s["chamfer_l1"]
            self.fscore_sum[c] += torch.as_tensor(s["fscore"], dtype=torch.float64, device=self.count.device)
            self.normal_sum[c] += s["normal_consistency"]
            self.count[c] += 1
            self.empty[c] += float(s["empty"])

    def compute(self) -> dict[str, torch.Tensor]:
        total = self.count.sum().clamp_min(1)
        per = self.count.clamp_min(1)
        nan = torch.tensor(float("nan"), dtype=torch.float64, device=self.count.device)
        has = self.count > 0
        return {
            "chamfer_l1": self.chamfer_sum.sum() / total,
            "fscore": self.fscore_sum.sum(0) / total,
            "normal_consistency": self.normal_sum.sum() / total,
            "chamfer_l1_per_category": torch.where(has, self.chamfer_sum / per, nan),
            "fscore_per_category": torch.where(has[:, None], self.fscore_sum / per[:, None], nan),
            "normal_consistency_per_category": torch.where(has, self.normal_sum / per, nan),
            "count_per_category": self.count,
            "empty_per_category": self.empty,
        }


__all__ = ["CHAMFER_KEYS", "EMPTY_CHAMFER", "SurfaceMetrics", "SurfaceSample", "fscore_key", "grid_surface",
           "sample_grids", "sample_mesh", "sample_triangles", "surface_scores"]
