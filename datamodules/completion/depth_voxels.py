"""One view of a procedural shape -> (partial 2.5D grid, complete solid grid), as in 3D-RecGAN++.

Grid convention (view-aligned, the same as the real 3D-RecGAN++ files, where the
2.5D surface lies within about one voxel of the target's low-z face):
arrays are indexed ``[i, j, k]`` = ``[x, y, depth]``; x to the camera's right, y
up in the image, ``k`` grows away from the camera (the camera looks along +k).
The object is rotated into the camera frame (:func:`lit3d.sensing.placement.camera_rotation`) and
scaled/centred so that its longest side spans ``res - 2 * margin`` voxels (``margin`` =
:data:`lit3d.sensing.placement.GRID_MARGIN` unless given).

Steps for one sample:
1. camera rotation from (azimuth, elevation, roll) in degrees;
2. normalisation from the mesh vertices in the camera frame;
3. target: union of the primitives' analytic inside tests at voxel centres, each
   primitive grown by half a voxel (a conservative, binvox-like filled solid);
4. depth image (pyrender, EGL) through the sensor's camera (:mod:`lit3d.sensing.sensor`:
   orthographic at ``render_factor * res`` pixels a side, or 3D-RecGAN++'s pinhole camera);
5. back-projection: each foreground pixel's surface point (with the sensor's range noise and
   holes), pushed :data:`~lit3d.sensing.placement.SURFACE_PUSH` (a quarter voxel) along its ray
   into the object, marks its voxel -> partial surface grid at ``res`` (noise-free, >95% of these voxels are
   target voxels with the conservative target of step 3); the sensor may misregister the points by a sub-voxel
   shift and mirror ``i`` (3D-RecGAN++'s handedness);
6. the network input is that grid max-pooled by ``input_factor``.
"""
from __future__ import annotations

import itertools

import numpy as np

from datamodules.completion.furniture import Shape, shape_mesh
from datamodules.completion.mesh_shapes import MeshShape
from datamodules.completion.voxel_cache import max_pool_bool
from lit3d.geometry.solid_voxels import solid_voxels
from lit3d.render.camera import OrthoCamera, look_at, render_ortho_depth
from lit3d.sensing.sensor import Sensor, bin_points, make_sensor, render_perspective, sensed_points
from lit3d.sensing.placement import GRID_MARGIN, SURFACE_PUSH, camera_rotation

# Analogues of the 3D-RecGAN++ view sets: same-view 5x5x5 (125 views), cross-view
# 6x6x6 (216 views), as (azimuth, elevation, roll) grids. The two sets share no view.
SAME_VIEW_AXES = ((0.0, 72.0, 144.0, 216.0, 288.0), (0.0, 12.0, 24.0, 36.0, 48.0), (-10.0, -5.0, 0.0, 5.0, 10.0))
CROSS_VIEW_AXES = ((30.0, 90.0, 150.0, 210.0, 270.0, 330.0), (-6.0, 6.0, 18.0, 30.0, 42.0, 54.0),
                   (-12.5, -7.5, -2.5, 2.5, 7.5, 12.5))
VIEW_SETS = {
    "same": list(itertools.product(*SAME_VIEW_AXES)),
    "cross": list(itertools.product(*CROSS_VIEW_AXES)),
}


def view_index(view_set: str, idx: int) -> tuple[int, int, int]:
    """Flat index into a view set -> (a, b, c) grid indices (as in ``<id>_<a>_<b>_<c>.npz``)."""
    n = len(SAME_VIEW_AXES[0]) if view_set == "same" else len(CROSS_VIEW_AXES[0])
    return idx // (n * n), (idx // n) % n, idx % n


class ViewGeometry:
    """Object frame -> voxel frame for one view: ``v = ((R p) - centre) * scale + res/2`` (GL axes)."""

    def __init__(self, shape: Shape, rot: np.ndarray, res: int, margin: float = GRID_MARGIN):
        self.rot, self.res = rot, res
        verts = shape.vertices() @ rot.T
        lo, hi = verts.min(0), verts.max(0)
        self.centre = (lo + hi) / 2
        self.scale = (res - 2 * margin) / float(np.max(hi - lo))

    def to_voxel(self, p: np.ndarray) -> np.ndarray:
        """(N, 3) object points -> (N, 3) GL voxel-unit points, centred at 0 (range [-res/2, res/2])."""
        return (p @ self.rot.T - self.centre) * self.scale

    def voxel_centres_to_object(self, idx: np.ndarray) -> np.ndarray:
        """(N, 3) integer ``[i, j, k]`` grid indices -> (N, 3) object-frame voxel centres."""
        h = self.res / 2
        gl = np.stack([idx[:, 0] + 0.5 - h, idx[:, 1] + 0.5 - h, h - (idx[:, 2] + 0.5)], axis=1)
        return (gl / self.scale + self.centre) @ self.rot


def solid_occupancy(shape: Shape, geom: ViewGeometry, pad: float = 0.5) -> np.ndarray:
    """(res, res, res) bool filled solid from the analytic inside tests at voxel centres.

    ``pad`` (voxels) grows every primitive before the centre test: with 0.5 a voxel
    is set when it touches an axis-aligned box (a conservative, binvox-like
    voxelisation, so thin parts never vanish and the visible surface lies in the
    solid); 0 gives the plain centre-inside test. Each primitive is tested only on
    its own bounding box, with separable broadcasting (no index meshgrid).
    """
    res = geom.res
    occ = np.zeros((res, res, res), dtype=bool)
    h = res / 2
    # voxel index -> GL voxel units -> object frame: affine (A, b)
    flip = np.diag([1.0, 1.0, -1.0])
    g0 = np.array([0.5 - h, 0.5 - h, h - 0.5])
    a_obj = geom.rot.T @ flip / geom.scale
    b_obj = geom.rot.T @ (g0 / geom.scale + geom.centre)
    for prim in shape.primitives:
        gl = geom.to_voxel(prim.corners())
        ic = np.stack([gl[:, 0] + h, gl[:, 1] + h, h - gl[:, 2]], axis=1)
        lo = np.clip(np.floor(ic.min(0) - pad).astype(int) - 1, 0, res)
        hi = np.clip(np.ceil(ic.max(0) + pad).astype(int) + 1, 0, res)
        if np.any(hi <= lo):
            continue
        inv = np.linalg.inv(prim.transform)
        m = (inv[:3, :3] @ a_obj).astype(np.float32)
        t = (inv[:3, :3] @ b_obj + inv[:3, 3]).astype(np.float32)
        ii = np.arange(lo[0], hi[0], dtype=np.float32)[:, None, None]
        jj = np.arange(lo[1], hi[1], dtype=np.float32)[None, :, None]
        kk = np.arange(lo[2], hi[2], dtype=np.float32)[None, None, :]
        x, y, z = (m[r, 0] * ii + m[r, 1] * jj + m[r, 2] * kk + t[r] for r in range(3))
        inside = prim.inside(x, y, z, pad / geom.scale)
        occ[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]] |= inside
    return occ


def mesh_solid(shape: MeshShape, geom: ViewGeometry, spacing: float = 0.5) -> np.ndarray:
    """(res, res, res) bool solid of a real mesh on the view grid (:mod:`lit3d.geometry.solid_voxels`);
    ``spacing``: the surface samples' largest gap in voxels (0.5 / f mimics a grid f times finer)."""
    h = geom.res / 2
    gl = geom.to_voxel(shape.points)
    index_coords = np.stack([gl[:, 0] + h, gl[:, 1] + h, h - gl[:, 2]], axis=1)
    return solid_voxels(index_coords, shape.faces, geom.res, coarse=max(2, int(8 * spacing)), spacing=spacing)


def target_occupancy(shape: Shape | MeshShape, geom: ViewGeometry, pad: float = 0.5, spacing: float = 0.5) -> np.ndarray:
    """(res, res, res) bool target: analytic primitives (grown by ``pad`` voxels) or a real mesh's solid."""
    if isinstance(shape, MeshShape):
        return mesh_solid(shape, geom, spacing)
    return solid_occupancy(shape, geom, pad)


def surface_mesh(shape: Shape | MeshShape):
    """The shape's triangles as one trimesh (what the depth camera sees)."""
    return shape.mesh() if isinstance(shape, MeshShape) else shape_mesh(shape)


def render_depth(shape: Shape | MeshShape, geom: ViewGeometry, pixels: int) -> np.ndarray:
    """(pixels, pixels) float64 orthographic eye depth in voxel units (0 = background).

    Row 0 is the top of the image (GL +y). The camera sits at GL z = res looking along -z.
    """
    mesh = surface_mesh(shape)
    res = geom.res
    camera = OrthoCamera(half_width=res / 2, znear=1.0, zfar=3.0 * res)
    depth, _ = render_ortho_depth(geom.to_voxel(np.asarray(mesh.vertices)), np.asarray(mesh.faces),
                                  look_at([0.0, 0.0, float(res)]), pixels, camera)
    return depth


def max_pool(grid: np.ndarray, factor: int) -> np.ndarray:
    """(R, R, R) bool -> (R/f, R/f, R/f) bool, a voxel is set when any of its f^3 children is."""
    return max_pool_bool(grid, factor)


def make_sample(shape: Shape | MeshShape, view: tuple[float, float, float], target_res: int = 64, input_factor: int = 4,
                render_factor: int = 2, margin: float = GRID_MARGIN, pad: float = 0.5, push: float = SURFACE_PUSH,
                sensor: Sensor | str | dict | None = None, rng: np.random.Generator | None = None,
                with_target: bool = True) -> dict[str, np.ndarray]:
    """One view of ``shape`` -> dict(input=(r,r,r) bool, target=(R,R,R) bool, surface=(R,R,R) bool).

    ``R = target_res``, ``r = R / input_factor``; ``surface`` is the partial grid before pooling.
    ``sensor`` (:mod:`lit3d.sensing.sensor`: a name, a dict or a Sensor; default the
    orthographic, noise-free one) decides the camera, handedness and noise; ``rng`` draws the
    noise (required when the sensor is noisy). ``with_target=False`` leaves ``target`` None.
    With a raw-resolution sensor a real mesh's target is made on the target grid directly
    (:mod:`datamodules.completion.mesh_shapes`); a procedural one's at the raw grid, then pooled.
    """
    if target_res % input_factor:
        raise ValueError(f"target_res={target_res} is not divisible by input_factor={input_factor}")
    sensor = make_sensor(sensor)
    if sensor.raw_res and sensor.raw_res != target_res:
        if sensor.raw_res % target_res:
            raise ValueError(f"sensor raw_res={sensor.raw_res} is not a multiple of target_res={target_res}")
        f = sensor.raw_res // target_res
        direct = isinstance(shape, MeshShape)
        raw = make_sample(shape, view, sensor.raw_res, input_factor * f, max(1, render_factor // f), margin, pad,
                          push, sensor, rng, with_target=with_target and not direct)
        surface = max_pool(raw["surface"], f)
        if not with_target:
            target = None
        elif direct:  # the same normalisation as the raw grid's: margin / f voxels of the coarser grid
            target = target_occupancy(shape, ViewGeometry(shape, camera_rotation(*view), target_res, margin / f), pad,
                                      spacing=0.5 / f)
            if sensor.mirror_x:
                target = target[::-1].copy()
        else:
            target = max_pool(raw["target"], f)
        return {"input": max_pool(surface, input_factor), "target": target, "surface": surface}
    geom = ViewGeometry(shape, camera_rotation(*view), target_res, margin)
    target = target_occupancy(shape, geom, pad) if with_target else None
    if sensor.camera == "perspective":
        mesh = surface_mesh(shape)
        depth = render_perspective(geom.to_voxel(np.asarray(mesh.vertices)), np.asarray(mesh.faces), sensor,
                                   target_res, render_factor)
    else:
        depth = render_depth(shape, geom, render_factor * target_res)
    surface = bin_points(sensed_points(depth, sensor, target_res, render_factor, push, rng), target_res)
    if sensor.mirror_x:  # 3D-RecGAN++'s x axis points to the image's left
        surface = surface[::-1].copy()
        target = None if target is None else target[::-1].copy()
    return {"input": max_pool(surface, input_factor), "target": target, "surface": surface}
