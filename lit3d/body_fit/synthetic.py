"""Synthetic depth images of people, as the body fit's evaluation (:mod:`lit3d.body.fit_scores`) and the
regressor's training people (:mod:`datamodules.body.people`) both make them.

Camera: the ``lit3d-reconstruct`` default, the 3D-RecGAN++ pinhole (fov 49.124 degrees across both
sides of a 320x240 image, centred; :class:`Camera`, a :class:`lit3d.sensing.camera.Intrinsics`).
:func:`render`: z-depth of a camera-frame mesh. :func:`sensed_depth`: the same through a sensor of
:data:`lit3d.sensing.sensor.SENSORS` (``recgan``: misregistration, range noise, holes; its figures
are in voxels of a 256 grid, one voxel taken as the person's longest side / 256).
"""
from __future__ import annotations

import numpy as np

from lit3d.render.camera import render_pinhole_depth
from lit3d.sensing.camera import Intrinsics
from lit3d.sensing.sensor import RAW_RES, RECGAN_FOV_DEG, SENSORS, hole_mask

WIDTH, HEIGHT = 320, 240
FLIP = np.array([1.0, -1.0, -1.0])  # y up, facing +z  <->  camera frame (y down, z forward), facing the camera


class Camera(Intrinsics):
    """Pinhole intrinsics (pixel centres at integers, as :mod:`lit3d.sensing.camera`)."""

    @classmethod
    def default(cls, width: int = WIDTH, height: int = HEIGHT, fov_deg: float = RECGAN_FOV_DEG) -> "Camera":
        """lit3d-reconstruct's default camera for a ``width x height`` image."""
        return cls.from_fov(fov_deg, width, height)


def render(verts_cam: np.ndarray, faces: np.ndarray, cam, width: int = WIDTH, height: int = HEIGHT) -> np.ndarray:
    """``(H, W) float32`` z-depth (metres, 0 = background) of a camera-frame mesh ``(V, 3)``, ``(F, 3)``."""
    depth = render_pinhole_depth(np.asarray(verts_cam, np.float64) * FLIP, faces, np.eye(4), width, height,
                                 cam.fx, cam.fy, cam.cx + 0.5, cam.cy + 0.5, znear=0.05, zfar=100.0)
    return depth.astype(np.float32)


def sensed_depth(verts_cam: np.ndarray, faces: np.ndarray, cam, rng: np.random.Generator,
                 sensor: str = "recgan", width: int = WIDTH, height: int = HEIGHT) -> tuple[np.ndarray, dict]:
    """The ``(H, W) float32`` depth image of a camera-frame mesh through ``sensor``'s noise (module
    doc), and what was applied."""
    s = SENSORS[sensor]
    voxel = float(np.ptp(verts_cam, axis=0).max()) / RAW_RES
    shift = rng.uniform(-1.0, 1.0, 3) * s.misregistration * voxel
    depth = render(verts_cam + shift, faces, cam, width, height).astype(np.float64)
    fg = depth > 0
    hole_px = s.hole_size * voxel * cam.fy / float(np.median(depth[fg])) if fg.any() else 0.0
    if s.hole_fraction:
        fg &= ~hole_mask(fg, s.hole_fraction, hole_px, rng)
    noise = rng.normal(0.0, s.depth_noise * voxel, depth.shape) if s.depth_noise else 0.0
    depth = np.where(fg, depth + noise, 0.0).astype(np.float32)
    return depth, {"sensor": sensor, "voxel_m": voxel, "shift_m": shift.tolist(), "hole_px": hole_px,
                   "depth_noise_m": s.depth_noise * voxel}
