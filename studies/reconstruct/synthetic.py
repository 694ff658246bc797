"""A 320x240 16-bit depth PNG (mm) of a mesh 1.5 m in front of the 3D-RecGAN++ camera, to try
``lit3d-reconstruct`` on (the rendering: :mod:`lit3d.reconstruct.synthetic`).

    python -m studies.reconstruct.synthetic ../shared/data/meshes/cow.obj cow.png
    python -m studies.reconstruct.synthetic chair chair.png      # a built-in procedural chair (no files needed)

A built-in name (``chair``, ``table``, ``bench``, ``couch``: the procedural furniture of
:mod:`datamodules.completion.furniture`, seed 0, or ``NAME:SEED``) stands for a mesh file.
"""
from __future__ import annotations

import io
import sys
from pathlib import Path

import numpy as np
import trimesh
from PIL import Image

from lit3d.reconstruct.backproject import RECGAN_FOV_DEG, Intrinsics
from lit3d.reconstruct.synthetic import pose_in_front, render_depth_pinhole
from lit3d.utils.io import atomic_write_bytes


BUILT_IN = ("chair", "table", "bench", "couch")


def load_mesh(src: str):
    """A mesh file, or a built-in procedural shape ``NAME`` / ``NAME:SEED`` (see the module doc)."""
    name, _, seed = src.partition(":")
    if name in BUILT_IN and not Path(src).exists():
        from datamodules.completion.furniture import make_shape, shape_mesh

        return shape_mesh(make_shape(name, np.random.default_rng(int(seed or 0))))
    return trimesh.load(src, force="mesh")


def main(argv: list[str] | None = None) -> None:
    """``python -m studies.reconstruct.synthetic MESH OUT.png``: a 320x240 16-bit depth PNG (mm) of
    ``MESH`` 1.5 m in front of the 3D-RecGAN++ camera, to try ``lit3d-reconstruct`` on."""
    src, out = (sys.argv[1:] if argv is None else argv)[:2]
    depth = render_depth_pinhole(pose_in_front(load_mesh(src)),
                                 Intrinsics.from_fov(RECGAN_FOV_DEG, 320, 240), 320, 240)
    buf = io.BytesIO()
    Image.fromarray(np.round(depth * 1000).astype(np.uint16)).save(buf, format="PNG")
    print(atomic_write_bytes(out, buf.getvalue()))


if __name__ == "__main__":
    main()
