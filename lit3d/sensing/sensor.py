"""How the 2.5D input of a completion sample is sensed: camera, handedness, noise.

Two cameras, both looking along ``+k`` of the view-aligned grid of
:mod:`lit3d.sensing.placement` (``[i, j, k]`` = ``[x, y up, depth]``):

- ``ortho``: the project's original orthographic camera (rays parallel to ``k``).
- ``perspective``: 3D-RecGAN++'s pinhole camera (``Data_preprocess/depth_2_pc_2_vox.py`` of its
  release: one field of view of 49.124 degrees across both image sides, principal point at
  the centre). The camera sits on the grid's optical axis, ``distance`` grid sides from the
  grid centre; the image has ``render_factor`` pixels per voxel at that distance. Each
  foreground pixel is back-projected along its own ray.

``pixels_per_voxel`` (perspective; 0 = the generator's ``render_factor``): image pixels per
voxel at the grid centre's distance; below 1 the sensed surface is sparser than the grid.
``raw_res`` (0 = off): make both grids at this side and max-pool them to the requested one,
as the release's 256^3 grids are pooled for training (the pooled target is then the
any-of-children occupancy of a finer voxelisation, as in the real data).

3D-RecGAN++'s grids are mirror images of the project's original ones (its ``x`` axis points
to the image's left): ``mirror_x`` flips axis ``i`` of both the input and the target.

Noise, in voxels of a 256 grid (the release's resolution; scaled to the grid being made):

- ``misregistration``: one shift per sample, uniform in ``[-m, m]`` per axis, of the sensed
  points against the target. In the release every 2.5D voxel outside its target lies one
  voxel (at 256^3) from it: a sub-voxel misregistration, not range noise
  (:mod:`studies.completion.input_stats` measures it).
- ``depth_noise``: standard deviation of independent per-pixel range noise.
- ``hole_fraction``: share of foreground pixels dropped in blobs of about ``hole_size`` pixels
  (a smoothed random field thresholded at the matching quantile).

:data:`SENSORS` holds the named settings: ``ortho`` (the original data) and ``recgan``
(perspective, mirrored, calibrated against the released sample; see the README, "Synthetic
data in the 3D-RecGAN++ geometry").
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from lit3d.render.camera import look_at, render_pinhole_depth

RECGAN_FOV_DEG = 49.124
RAW_RES = 256  # the resolution the noise figures refer to


@dataclass(frozen=True)
class Sensor:
    """Camera and noise model of the 2.5D input (see the module doc; lengths in 256-grid voxels)."""

    camera: str = "ortho"
    fov_deg: float = RECGAN_FOV_DEG
    distance: float = 2.0
    mirror_x: bool = False
    misregistration: float = 0.0
    depth_noise: float = 0.0
    hole_fraction: float = 0.0
    hole_size: float = 4.0
    raw_res: int = 0
    pixels_per_voxel: float = 0.0

    def __post_init__(self):
        if self.camera not in ("ortho", "perspective"):
            raise ValueError(f"sensor camera {self.camera!r}: expected 'ortho' or 'perspective'")
        if not 0 < self.fov_deg < 180:
            raise ValueError(f"sensor fov_deg {self.fov_deg}: expected a value in (0, 180)")
        half = math.tan(math.radians(self.fov_deg) / 2)
        if self.camera == "perspective" and (self.distance - 0.5) * half < 0.5:
            raise ValueError(f"sensor distance {self.distance} grid sides: the grid's near face does not fit "
                             f"a {self.fov_deg} degree field of view (needs >= {0.5 + 0.5 / half:.2f})")
        if self.raw_res < 0:
            raise ValueError(f"sensor raw_res {self.raw_res}: expected 0 (off) or a grid side")
        if self.misregistration < 0 or self.depth_noise < 0 or not 0 <= self.hole_fraction < 1:
            raise ValueError(f"sensor noise must be >= 0 and hole_fraction in [0, 1): {self}")

    @property
    def noisy(self) -> bool:
        return bool(self.misregistration or self.depth_noise or self.hole_fraction)

    def as_dict(self) -> dict:
        return asdict(self)


SENSORS = {
    "ortho": Sensor(),
    # calibrated at 64^3 on ../shared/data/recgan_sample (python -m studies.completion.input_stats;
    # README "Synthetic data in the 3D-RecGAN++ geometry"): made at 256^3 and pooled, as the release
    "recgan": Sensor(camera="perspective", mirror_x=True, misregistration=0.75, depth_noise=0.25,
                     hole_fraction=0.15, hole_size=8.0, raw_res=RAW_RES, pixels_per_voxel=1.0),
}


def make_sensor(spec: str | dict | Sensor | None) -> Sensor:
    """A :class:`Sensor` from a name in :data:`SENSORS`, a dict of fields (``base:`` names the
    starting point), or a Sensor; None is the original orthographic sensor."""
    if spec is None:
        return SENSORS["ortho"]
    if isinstance(spec, Sensor):
        return spec
    if isinstance(spec, str):
        if spec not in SENSORS:
            raise ValueError(f"unknown sensor {spec!r}; known: {sorted(SENSORS)}")
        return SENSORS[spec]
    fields = dict(spec)
    base = make_sensor(fields.pop("base", None))
    unknown = set(fields) - set(base.as_dict())
    if unknown:
        raise ValueError(f"unknown sensor field(s) {sorted(unknown)}; known: {sorted(base.as_dict())}")
    return Sensor(**{**base.as_dict(), **fields})


def pinhole_geometry(sensor: Sensor, res: int, render_factor: float) -> tuple[float, float, int]:
    """``(camera distance from the grid centre in voxels, focal length in pixels, image side)``."""
    dist = sensor.distance * res
    focal = (sensor.pixels_per_voxel or render_factor) * dist  # pixels per voxel at the grid centre
    side = int(math.ceil(2 * math.tan(math.radians(sensor.fov_deg) / 2) * focal))
    return dist, focal, side


def render_perspective(verts_gl: np.ndarray, faces: np.ndarray, sensor: Sensor, res: int,
                       render_factor: int) -> np.ndarray:
    """``(S, S) float64`` eye depth (voxels; 0 = background) of a mesh in centred GL voxel units.

    The camera sits at GL ``(0, 0, distance)`` looking along ``-z`` (towards ``+k``).
    """
    dist, focal, side = pinhole_geometry(sensor, res, render_factor)
    return render_pinhole_depth(verts_gl, faces, look_at([0.0, 0.0, dist]), side, side, focal, focal,
                                side / 2, side / 2, znear=0.1 * res, zfar=dist + 2 * res)


def hole_mask(fg: np.ndarray, fraction: float, size: float, rng: np.random.Generator) -> np.ndarray:
    """``(H, W) bool``: foreground pixels to drop, about ``fraction`` of ``fg`` in blobs of ``size`` px."""
    from scipy import ndimage

    if fraction <= 0 or not fg.any():
        return np.zeros_like(fg)
    field = ndimage.gaussian_filter(rng.standard_normal(fg.shape), sigma=max(size, 0.5) / 2)
    cut = np.quantile(field[fg], fraction)
    return fg & (field < cut)


def sensed_points(depth: np.ndarray, sensor: Sensor, res: int, render_factor: int, push: float,
                  rng: np.random.Generator | None) -> np.ndarray:
    """Foreground pixels of a depth image -> ``(N, 3) float64`` continuous grid indices ``[i, j, k]``.

    Range noise and holes are applied per pixel, each point moves ``push`` voxels further along
    its ray, then the whole set is misregistered by one random shift. ``i`` is not yet mirrored.

    Args:
        depth: ``(S, S)`` eye depth in voxels from :func:`render_perspective` (perspective) or
            the orthographic pass of :func:`datamodules.completion.depth_voxels.render_depth`.
    """
    h = res / 2
    fg = depth > 0
    scale = res / RAW_RES  # grid voxels per 256-grid voxel
    if sensor.noisy and rng is None:
        raise ValueError("a noisy sensor needs a random generator")
    if sensor.hole_fraction:
        fg &= ~hole_mask(fg, sensor.hole_fraction, sensor.hole_size, rng)
    rows, cols = np.nonzero(fg)
    d = depth[rows, cols].astype(np.float64)
    if sensor.depth_noise:
        d = d + rng.normal(0.0, sensor.depth_noise * scale, size=d.shape)
    if sensor.camera == "perspective":
        dist, focal, side = pinhole_geometry(sensor, res, render_factor)
        x = (cols + 0.5 - side / 2) * d / focal
        y = (side / 2 - rows - 0.5) * d / focal
        ray = np.stack([x, y, d], axis=1)
        ray /= np.linalg.norm(ray, axis=1, keepdims=True)
        pts = np.stack([x + h, y + h, d - dist + h], axis=1) + push * ray
    else:  # orthographic: the camera at GL z = res looks along -z; k = d - res/2
        f = depth.shape[0] / res
        pts = np.stack([(cols + 0.5) / f, res - (rows + 0.5) / f, d - h + push], axis=1)
    if sensor.misregistration:
        pts = pts + rng.uniform(-1.0, 1.0, size=3) * sensor.misregistration * scale
    return pts


def bin_points(pts: np.ndarray, res: int) -> np.ndarray:
    """``(N, 3)`` continuous grid indices -> ``(res, res, res) bool`` (points outside are dropped)."""
    idx = np.floor(pts).astype(np.int64)
    idx = idx[np.all((idx >= 0) & (idx < res), axis=1)]
    grid = np.zeros((res, res, res), dtype=bool)
    grid[idx[:, 0], idx[:, 1], idx[:, 2]] = True
    return grid
