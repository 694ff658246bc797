"""View geometry of the completion data: how an object is turned and placed in the voxel grids.

Grid convention (view-aligned, as in the 3D-RecGAN++ files): arrays are indexed ``[i, j, k]`` =
``[x, y, depth]``; x to the camera's right, y up in the image, ``k`` grows away from the camera.
The synthetic generator (:func:`datamodules.completion.depth_voxels.make_sample`) scales an object
so that its longest side spans ``R - 2 * GRID_MARGIN`` voxels and moves every sensed surface point
``SURFACE_PUSH`` voxels along its ray before binning; the inference pipeline
(:mod:`lit3d.reconstruct.grid`) places depth-image points with the same two numbers.
"""
from __future__ import annotations

import numpy as np

GRID_MARGIN = 1.0  # free voxels on each side of an object's longest extent in the target grid
SURFACE_PUSH = 0.25  # voxels each sensed surface point moves along its ray (into the object) before binning


def camera_rotation(azimuth: float, elevation: float, roll: float = 0.0) -> np.ndarray:
    """(3, 3) rotation object frame (y up) -> camera frame (OpenGL: x right, y up, camera looks along -z).

    The camera sits on the direction (cos e sin a, sin e, cos e cos a) from the object centre.
    """
    a, e, r = np.radians([azimuth, elevation, roll])
    z = np.array([np.cos(e) * np.sin(a), np.sin(e), np.cos(e) * np.cos(a)])
    x = np.cross([0.0, 1.0, 0.0], z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    rot = np.stack([x, y, z])
    c, s = np.cos(r), np.sin(r)
    roll_m = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    return roll_m @ rot
