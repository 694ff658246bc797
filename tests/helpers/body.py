"""The body-fit tests' camera (3D-RecGAN++'s field of view at 160 x 120) and a depth-image writer
(uint16 millimetres, as a depth sensor saves it)."""
from __future__ import annotations

import numpy as np
from PIL import Image

from lit3d.reconstruct.backproject import RECGAN_FOV_DEG, Intrinsics

W, H = 160, 120
INTR = Intrinsics.from_fov(RECGAN_FOV_DEG, W, H)


def save_depth_mm(path, depth):
    """Write ``depth`` ``(H, W)`` metres as a uint16 millimetre PNG."""
    Image.fromarray(np.round(np.asarray(depth) * 1000).astype(np.uint16)).save(path)
