"""A 320x240 16-bit depth PNG (mm) of a mesh 1.5 m in front of the 3D-RecGAN++ camera, to try
``lit3d-reconstruct`` on (the rendering: :mod:`lit3d.reconstruct.synthetic`).

    python -m studies.reconstruct.synthetic ../shared/data/meshes/cow.obj cow.png
"""
from __future__ import annotations

import io
import sys

import numpy as np
import trimesh
from PIL import Image

from lit3d.reconstruct.backproject import RECGAN_FOV_DEG, Intrinsics
from lit3d.reconstruct.synthetic import pose_in_front, render_depth_pinhole
from lit3d.utils.io import atomic_write_bytes


def main(argv: list[str] | None = None) -> None:
    """``python -m studies.reconstruct.synthetic MESH OUT.png``: a 320x240 16-bit depth PNG (mm) of
    ``MESH`` 1.5 m in front of the 3D-RecGAN++ camera, to try ``lit3d-reconstruct`` on."""
    src, out = (sys.argv[1:] if argv is None else argv)[:2]
    depth = render_depth_pinhole(pose_in_front(trimesh.load(src, force="mesh")),
                                 Intrinsics.from_fov(RECGAN_FOV_DEG, 320, 240), 320, 240)
    buf = io.BytesIO()
    Image.fromarray(np.round(depth * 1000).astype(np.uint16)).save(buf, format="PNG")
    print(atomic_write_bytes(out, buf.getvalue()))


if __name__ == "__main__":
    main()
