"""Camera-frame points <-> the completion network's voxel grids, in the training geometry.

Grid convention (as in :mod:`lit3d.sensing.placement` and the 3D-RecGAN++ files):
``[i, j, k]`` = ``[x right, y up in the image, depth away from the camera]``. From the
camera frame of :mod:`lit3d.reconstruct.backproject` (``y`` down, ``z`` forward, metres)::
    i = (x - c_x) s + R/2,   j = -(y - c_y) s + R/2,   k = (z - c_z) s + R/2

with ``s`` voxels per metre and ``c`` the placement centre. What the checkpoint was trained
with decides ``c`` and ``s`` (:class:`GridGeometry`, read from ``checkpoint["lit3d"]["data"]``):

- ``source: synth`` (the built-in data): the *whole* object's bounding box in the view frame,
  longest side ``R - 2 margin`` voxels. A depth image shows the silhouette's x/y extent but
  not how deep the object goes: the hidden depth extent is estimated as
  ``max(visible depth range, width)`` and the box starts at the nearest visible point.
- ``source: recgan`` (the 3D-RecGAN++ release): the *visible* points' bounding box, longest
  side ``raw_res - 1`` steps of a ``raw_res`` grid, centred, then max-pooled to ``R``.

Each point moves ``push`` voxels further along its ray before binning (as in training), and
the network input is the ``R`` grid max-pooled by ``input_factor``. When the training grids
were mirror images (``mirror_x``: the 3D-RecGAN++ release, whose ``x`` axis points to the
image's left, and synthetic data made with its sensor), the network sees the grid flipped
along ``i`` and its prediction is flipped back (:meth:`GridGeometry.to_network`).
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from lit3d.sensing.sensor import make_sensor
from lit3d.sensing.placement import GRID_MARGIN, SURFACE_PUSH
from lit3d.metrics.mesh import surface_samples


@dataclass(frozen=True)
class GridGeometry:
    """How the training data placed an object in the grids.

    Attributes:
        source: "synth" (whole-object box, estimated depth) or "recgan" (visible-points box).
        target_res: ``R``, the output grid side.
        input_factor: the network input is ``R / input_factor`` a side.
        margin: free voxels on each side of the longest extent.
        push: voxels each point moves along its ray before binning.
        note: how the geometry was found (e.g. a default for an older checkpoint), or "".
        mirror_x: the training grids' ``i`` axis points to the image's left.
    """
    source: str
    target_res: int
    input_factor: int
    margin: float
    push: float
    note: str = ""
    mirror_x: bool = False

    def to_network(self, grid: np.ndarray) -> np.ndarray:
        """A grid in this module's frame <-> the network's frame (its own inverse)."""
        return np.ascontiguousarray(grid[::-1]) if self.mirror_x else grid

    @property
    def input_res(self) -> int:
        return self.target_res // self.input_factor

    @classmethod
    def from_checkpoint(cls, data_cfg: dict | None, net_cfg: dict) -> "GridGeometry":
        """The geometry of a completion checkpoint: its stored data config, checked against the
        net's ``in_res``/``out_res`` (today's layout: :func:`lit3d.completion.checkpoint_upgrade.upgrade_checkpoint`
        reads an old one so); a checkpoint without a data config gets the synthetic
        geometry at the net's sizes, with a note."""
        out_res, in_res = int(net_cfg["out_res"]), int(net_cfg["in_res"])
        if not data_cfg:
            return cls("synth", out_res, out_res // in_res, GRID_MARGIN, SURFACE_PUSH,
                       note="checkpoint has no data config: assumed the built-in synthetic geometry")
        source = str(data_cfg.get("source", "synth"))
        factor = int(data_cfg.get("input_factor", out_res // in_res))
        note = ""
        if int(data_cfg.get("target_res", out_res)) != out_res or out_res // factor != in_res:
            note = (f"data config target_res={data_cfg.get('target_res')} input_factor={factor} does not match "
                    f"the net ({in_res}^3 -> {out_res}^3): the net's sizes are used")
            factor = out_res // in_res
        if source == "recgan":
            raw = int((data_cfg.get("recgan") or {}).get("raw_res") or 256)
            # voxel step = extent / (raw - 1) in a raw^3 grid, pooled to R: margin of half a raw voxel
            return cls("recgan", out_res, factor, 0.5 * out_res / raw, 0.0, note, mirror_x=True)
        sensor = make_sensor((data_cfg.get("render") or {}).get("sensor"))
        shrink = out_res / sensor.raw_res if sensor.raw_res else 1.0  # made finer, then pooled
        return cls("synth", out_res, factor, GRID_MARGIN * shrink, SURFACE_PUSH * shrink, note, mirror_x=sensor.mirror_x)

    def as_dict(self) -> dict:
        return {**asdict(self), "input_res": self.input_res}


@dataclass(frozen=True)
class Placement:
    """Camera frame <-> continuous grid index coordinates for one image (see the module doc)."""
    centre: tuple[float, float, float]
    scale: float  # voxels per metre
    res: int

    def to_index(self, points: np.ndarray) -> np.ndarray:
        """``(N, 3)`` camera-frame metres -> ``(N, 3) float64`` continuous ``[i, j, k]`` (voxel
        ``[a, b, c]`` spans ``[a, a+1)``...)."""
        c, h = np.asarray(self.centre), self.res / 2
        q = (np.asarray(points, dtype=np.float64) - c) * self.scale
        return np.stack([q[:, 0] + h, h - q[:, 1], q[:, 2] + h], axis=1)

    def to_camera(self, index: np.ndarray) -> np.ndarray:
        """Inverse of :meth:`to_index`: ``(N, 3)`` continuous indices -> camera-frame metres."""
        idx, h = np.asarray(index, dtype=np.float64), self.res / 2
        q = np.stack([idx[:, 0] - h, h - idx[:, 1], idx[:, 2] - h], axis=1)
        return q / self.scale + np.asarray(self.centre)

    def as_dict(self) -> dict:
        return {"centre_m": [float(x) for x in self.centre], "voxels_per_metre": float(self.scale),
                "voxel_size_m": 1.0 / float(self.scale), "res": self.res}


def fit_placement(points: np.ndarray, geom: GridGeometry) -> Placement:
    """Centre and scale for ``(N, 3)`` visible camera-frame points in ``geom``'s training geometry."""
    lo, hi = points.min(0), points.max(0)
    ext = hi - lo
    centre = (lo + hi) / 2
    if geom.source == "synth":
        depth_ext = max(float(ext[2]), float(ext[0]))  # hidden depth: at least as deep as wide
        ext = np.array([ext[0], ext[1], depth_ext])
        centre[2] = lo[2] + depth_ext / 2
    longest = float(ext.max())
    if longest <= 0:
        longest = 1e-3
    return Placement(tuple(float(c) for c in centre), (geom.target_res - 2 * geom.margin) / longest, geom.target_res)


def voxelise_points(points: np.ndarray, placement: Placement, push: float = 0.0) -> tuple[np.ndarray, int]:
    """Bin camera-frame points into ``(R, R, R) bool``; each point first moves ``push`` voxels
    further along its ray (away from the camera at the origin).

    Returns:
        ``(grid, outside)``: the occupancy and how many points fell outside the grid.
    """
    p = np.asarray(points, dtype=np.float64)
    if push:
        p = p + p / np.linalg.norm(p, axis=1, keepdims=True).clip(1e-12) * (push / placement.scale)
    idx = np.floor(placement.to_index(p)).astype(np.int64)
    r = placement.res
    inside = np.all((idx >= 0) & (idx < r), axis=1)
    grid = np.zeros((r, r, r), dtype=bool)
    idx = idx[inside]
    grid[idx[:, 0], idx[:, 1], idx[:, 2]] = True
    return grid, int((~inside).sum())


def solid_voxels(mesh, placement: Placement, samples_per_voxel: float = 8.0) -> np.ndarray:
    """``(R, R, R) bool`` solid voxelisation of a camera-frame mesh (a trimesh): dense surface
    samples mark their voxels (so thin parts are kept, as in the conservative training targets),
    a one-voxel closing seals sample gaps and small holes, and enclosed cavities are filled."""
    from scipy import ndimage

    r = placement.res
    area_vox = float(mesh.area) * placement.scale ** 2
    n = int(np.clip(samples_per_voxel * area_vox, 10_000, 2_000_000))
    idx = np.floor(placement.to_index(surface_samples(mesh, n=n, seed=0, normalise=False))).astype(np.int64)
    idx = idx[np.all((idx >= 0) & (idx < r), axis=1)]
    occ = np.zeros((r, r, r), dtype=bool)
    occ[idx[:, 0], idx[:, 1], idx[:, 2]] = True
    closed = ndimage.binary_closing(np.pad(occ, 2), iterations=1)[2:-2, 2:-2, 2:-2] | occ
    return ndimage.binary_fill_holes(closed)
