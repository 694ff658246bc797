"""Score predicted shapes against target shapes paired by file stem (``lit3d-eval-folder PRED_DIR
--targets TARGET_DIR``; the reader: :mod:`lit3d.completion.target_pairs`).

Per pair, with the point-cloud library :mod:`lit3d.metrics.clouds` / :mod:`lit3d.metrics.nearest`:

1. **Frame**: meshes as stored (prediction and target must share one frame and unit; nothing is
   centred, scaled or aligned). A grid's surface is its marching-cubes mesh
   (:func:`lit3d.metrics.surface.grid_surface`) in the ``mesh_frame``: ``unit`` = the grid is the
   cube ``[-0.5, 0.5]^3`` (lit3d-eval's frame), ``voxel`` = vertex ``(x, y, z)`` at grid index
   ``[x, y, z]``.
2. **Samples**: ``points`` points uniformly by area on each surface, each with its face's unit
   normal, with one seed for both (identical surfaces give identical samples and score perfectly).
3. With ``d_pt`` each predicted point's distance to the nearest target point and ``d_tp`` the reverse:

   - ``chamfer_l1`` = ``(mean d_pt + mean d_tp) / 2``: unsquared distances, the two directions
     averaged (convention ``"l1"``: Occupancy Networks' Chamfer-L1), in the targets' units;
   - ``chamfer_l2`` = ``mean d_pt^2 + mean d_tp^2``: squared distances, the two directions summed
     (convention ``"pytorch3d"``: ``pytorch3d.loss.chamfer_distance``'s defaults, GRNet's CD-L2), in
     squared units;
   - ``fscore_<f>pct`` = ``2 P R / (P + R)`` with ``P = mean(d_pt <= tau)`` (``precision_<f>pct``),
     ``R = mean(d_tp <= tau)`` (``recall_<f>pct``), ``tau = f x`` the diagonal of the target surface's
     axis-aligned bounding box (of the vertices its faces use; lit3d-eval's ``bbox_diagonal``);
   - ``normal_consistency`` = mean over both directions of ``|n . n_nearest|`` (unoriented, 1 = parallel).
4. **IoU** (volumetric) when both shapes are solids: grids, or meshes that are watertight (after
   merging coincident vertices). Two grids of one shape: compared voxel by voxel. Two meshes: both
   voxelised (:func:`lit3d.geometry.solid_voxels.solid_voxels`: the surface's voxels plus the
   enclosed inside) on one cube grid of ``resolution`` voxels a side that holds both meshes' bounding
   boxes with one empty voxel around. A mesh and a (cubic) grid: the mesh voxelised on the grid's own
   voxels, in the ``mesh_frame``. Otherwise the pair's IoU is None and ``iou_skipped`` says why.

:func:`summarise` gives each measure's mean over the pairs with a 95% percentile bootstrap interval
(:func:`lit3d.metrics.bootstrap.mean_ci`).
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from lit3d.completion.target_pairs import Shape, ShapePair, read_shape
from lit3d.geometry.solid_voxels import solid_voxels
from lit3d.metrics.bootstrap import mean_ci
from lit3d.metrics.voxel import occupancy_iou
from lit3d.metrics.surface import (CHAMFER_KEYS, SurfaceSample, fscore_key, grid_surface, sample_mesh, sample_triangles,
                                   surface_scores)
from lit3d.render.convert import ShapeError

MESH_FRAMES = ("unit", "voxel")


@dataclass(frozen=True)
class TargetScoring:
    """The settings of a scoring: ``points`` per surface, F-score thresholds ``fscore_at`` (shares of
    the target's bounding-box diagonal), sampling ``seed``, ``threshold`` of prediction grids,
    ``mesh_frame`` of grids beside meshes (``unit`` | ``voxel``) and the IoU grid's ``resolution``."""

    points: int
    fscore_at: tuple[float, ...]
    seed: int = 0
    threshold: float = 0.5
    mesh_frame: str = "unit"
    resolution: int = 64

    def check(self) -> None:
        """ValueError naming the option of a setting out of range."""
        if self.mesh_frame not in MESH_FRAMES:
            raise ValueError(f"--mesh-frame {self.mesh_frame}: expected one of {', '.join(MESH_FRAMES)}")
        if not 0 < self.threshold <= 1:
            raise ValueError(f"--threshold {self.threshold}: expected a value in (0, 1]")
        if self.points < 1:
            raise ValueError(f"--points {self.points}: expected at least 1")
        if not self.fscore_at or min(self.fscore_at) <= 0:
            raise ValueError(f"--fscore-at {list(self.fscore_at)}: expected shares of the diagonal > 0")
        if self.resolution < 8:
            raise ValueError(f"--resolution {self.resolution}: expected at least 8 voxels a side")


def measure_keys(fscore_at: Sequence[float]) -> list[str]:
    """The summarised measures in table order: Chamfer-L1, Chamfer-L2, F-score at each threshold,
    normal consistency, IoU."""
    return [*CHAMFER_KEYS, *(fscore_key(f) for f in fscore_at), "normal_consistency", "iou"]


def grid_vertices_to_frame(vertices: np.ndarray, side: int, frame: str) -> np.ndarray:
    """Unit-frame vertices ``(V, 3)`` of a grid of ``side`` voxels in ``frame`` (module doc)."""
    return vertices if frame == "unit" else (vertices + 0.5) * side - 0.5


def surface_sample(shape: Shape, cfg: TargetScoring) -> SurfaceSample:
    """``cfg.points`` samples on the surface of a mesh, or of a grid's marching-cubes mesh in ``cfg.mesh_frame``."""
    if shape.mesh is not None:
        sample = sample_mesh(shape.mesh, cfg.points, cfg.seed)
    else:
        verts, faces = grid_surface(shape.grid)
        verts = grid_vertices_to_frame(verts, max(shape.grid.shape), cfg.mesh_frame)
        sample = sample_triangles(verts, faces, cfg.points, cfg.seed)
    if sample is None:
        raise ShapeError(f"{shape.path}: surface of zero area: nothing to sample")
    return sample


def pair_surface_scores(pred: SurfaceSample, target: SurfaceSample, fscore_at: Sequence[float]) -> dict[str, float]:
    """Chamfer-L1/-L2, precision, recall and F-score at each of ``fscore_at`` and normal consistency of
    one prediction's samples against its target's (:func:`lit3d.metrics.surface.surface_scores`, one
    value per key)."""
    scores = surface_scores(pred, target, fscore_at)
    out = {key: scores[key] for key in CHAMFER_KEYS}
    for k, f in enumerate(fscore_at):
        key = fscore_key(f)
        for measure in ("fscore", "precision", "recall"):
            out[key.replace("fscore", measure, 1)] = float(scores[measure][k])
    out["normal_consistency"] = scores["normal_consistency"]
    return out


def is_watertight(mesh) -> bool:
    """Closed and manifold once coincident vertices are merged (trimesh's ``is_watertight``)."""
    merged = mesh.copy()
    merged.merge_vertices()
    return bool(merged.is_watertight)


def _mesh_arrays(mesh) -> tuple[np.ndarray, np.ndarray]:
    return np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces, np.int64)


def mesh_pair_grids(pred, target, resolution: int) -> tuple[np.ndarray, np.ndarray]:
    """Solid ``(R, R, R)`` bool grids of two meshes on one cube grid holding both bounding boxes
    (of the vertices the faces use), one empty voxel around them (module doc)."""
    corners = np.concatenate([v[f].reshape(-1, 3) for v, f in map(_mesh_arrays, (pred, target))])
    lo, hi = corners.min(0), corners.max(0)
    scale = (resolution - 2) / float((hi - lo).max())
    centre = (lo + hi) / 2
    grids = []
    for mesh in (pred, target):
        v, f = _mesh_arrays(mesh)
        grids.append(solid_voxels((v - centre) * scale + resolution / 2, f, resolution))
    return grids[0], grids[1]


def mesh_on_grid(mesh, side: int, frame: str) -> np.ndarray:
    """Solid ``(side, side, side)`` bool grid of a mesh on a grid's own voxels, the mesh in ``frame``."""
    v, f = _mesh_arrays(mesh)
    index = (v + 0.5) * side if frame == "unit" else v + 0.5  # continuous voxel-index coordinates
    return solid_voxels(index, f, side)


def volume_iou(pred: Shape, target: Shape, cfg: TargetScoring) -> tuple[float | None, str]:
    """``(IoU, "")`` of two solids, or ``(None, why not)`` (module doc)."""
    for shape in (pred, target):
        if shape.mesh is not None and not is_watertight(shape.mesh):
            return None, f"{shape.path.name} is not watertight"
    if pred.grid is not None and target.grid is not None:
        if pred.grid.shape != target.grid.shape:
            return None, f"grids of shapes {pred.grid.shape} and {target.grid.shape}"
        return occupancy_iou(pred.grid, target.grid), ""
    if pred.mesh is not None and target.mesh is not None:
        return occupancy_iou(*mesh_pair_grids(pred.mesh, target.mesh, cfg.resolution)), ""
    grid, mesh = (pred.grid, target.mesh) if pred.grid is not None else (target.grid, pred.mesh)
    if len(set(grid.shape)) != 1:
        return None, f"a mesh beside a non-cubic grid of shape {grid.shape}"
    voxelised = mesh_on_grid(mesh, grid.shape[0], cfg.mesh_frame)
    return occupancy_iou(*((grid, voxelised) if pred.grid is not None else (voxelised, grid))), ""


def score_pair(pair: ShapePair, cfg: TargetScoring) -> dict:
    """One row of metrics.json: the files, their kinds, the surface measures and IoU of ``pair``."""
    pred, target = read_shape(pair.prediction, cfg.threshold), read_shape(pair.target)
    row = {"stem": pair.stem, "prediction": pair.prediction.name, "target": pair.target.name,
           "kinds": f"{pred.kind}/{target.kind}"}
    row.update(pair_surface_scores(surface_sample(pred, cfg), surface_sample(target, cfg), cfg.fscore_at))
    row["iou"], why = volume_iou(pred, target, cfg)
    if why:
        row["iou_skipped"] = why
    return row


def summarise(rows: Sequence[dict], keys: Sequence[str], seed: int = 0, level: float = 0.95) -> dict[str, dict]:
    """``key -> {"mean", "low", "high", "pairs"}``: the mean of each measure over the rows that have it
    (IoU: the pairs where it was measured) and its percentile bootstrap ``level`` interval (None
    bounds with fewer than 2 pairs, None everywhere with none)."""
    out = {}
    for key in keys:
        values = [r[key] for r in rows if r.get(key) is not None]
        mean, low, high = mean_ci(values, level, seed) if values else (None, None, None)
        out[key] = {k: (None if v is None or not np.isfinite(v) else float(v))
                    for k, v in (("mean", mean), ("low", low), ("high", high))}
        out[key]["pairs"] = len(values)
    return out


def score_target_folder(pairs: Sequence[ShapePair], cfg: TargetScoring) -> tuple[list[dict], dict[str, dict]]:
    """``(rows, means)``: :func:`score_pair` of every pair and :func:`summarise` of them."""
    cfg.check()
    rows = [score_pair(pair, cfg) for pair in pairs]
    return rows, summarise(rows, measure_keys(cfg.fscore_at), cfg.seed)


__all__ = ["CHAMFER_KEYS", "MESH_FRAMES", "TargetScoring", "is_watertight", "measure_keys",
           "mesh_on_grid", "mesh_pair_grids", "pair_surface_scores", "score_pair", "score_target_folder",
           "summarise", "surface_sample", "volume_iou"]
