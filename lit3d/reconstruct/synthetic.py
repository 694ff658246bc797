"""Depth images of known meshes through a pinhole camera, for round-trip checks and benchmarks.

The mesh is posed in the camera frame of :mod:`lit3d.reconstruct.backproject` (metres, ``y``
down, ``z`` forward) and rendered with the project's EGL pyrender path
(:func:`lit3d.render.camera.render_pinhole_depth`), whose depth buffer pyrender linearises to
z-depth (exact for perspective cameras). A depth PNG of a mesh to try ``lit3d-reconstruct`` on, from the
checkout: ``python -m studies.reconstruct.synthetic MESH OUT.png``.
"""
from __future__ import annotations

import numpy as np

from lit3d.reconstruct.backproject import Intrinsics
from lit3d.geometry.normalise import normalise_vertices
from lit3d.render.camera import render_pinhole_depth
from lit3d.sensing.placement import camera_rotation


def pose_in_front(mesh, distance: float = 1.5, size: float = 0.6, azimuth: float = 30.0,
                  elevation: float = 20.0, up_axis: int = 1):
    """A copy of ``mesh`` centred on the optical axis at ``distance`` metres, longest side ``size``
    metres, seen from ``azimuth``/``elevation`` degrees (object ``up_axis`` points up in the image)."""
    m = mesh.copy()
    v, _ = normalise_vertices(np.asarray(m.vertices, dtype=np.float64))
    if up_axis != 1:  # bring the object's up axis to +y
        v = np.roll(v, 1 - up_axis, axis=1)
    gl = v @ camera_rotation(azimuth, elevation).T  # object (y up) -> GL camera axes
    m.vertices = gl * np.array([size, -size, -size]) + np.array([0.0, 0.0, distance])  # GL -> camera frame
    return m


def render_depth_pinhole(mesh, intr: Intrinsics, width: int, height: int) -> np.ndarray:
    """``(H, W) float32`` z-depth in metres (0 = background) of a camera-frame mesh."""
    verts = np.asarray(mesh.vertices, dtype=np.float64) * np.array([1.0, -1.0, -1.0])  # camera -> GL
    # our cx/cy address the pixel centre (see backproject's doc); the renderer's the pixel corner
    depth = render_pinhole_depth(verts, np.asarray(mesh.faces), np.eye(4), width, height, intr.fx, intr.fy,
                                 intr.cx + 0.5, intr.cy + 0.5, znear=0.05, zfar=100.0)
    return depth.astype(np.float32)
