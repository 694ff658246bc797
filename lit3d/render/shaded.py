"""Shaded pictures of a mesh: the project's G-buffer pass + one MatCap style, for figures.

:func:`shaded_views` is the one place figures turn a mesh into what a person reads (completion
voxel renders, the reconstruction picture, the canonical contact sheets).
"""
from __future__ import annotations

import numpy as np

from lit3d.render.gbuffer import RenderConfig, render_gbuffer
from lit3d.render.styles import apply_styles


def shaded_views(mesh, directions, size: int = 256, style: str = "clay_studio", extent: float = 0.9,
                 background: float = 1.0, distance: float = 3.0) -> np.ndarray:
    """Orthographic shaded renders of a mesh already placed in normalised GL units.

    Args:
        mesh: a ``trimesh.Trimesh`` (GL frame: x right, y up, z towards the default camera),
            not re-normalised here, so several meshes of one figure share one scale.
        directions: ``(V, 3)`` view directions from the shape towards the camera (any length).
        size: image side in pixels.
        style: a MatCap style of :mod:`lit3d.render.style_library`.
        extent: orthographic half-width in mesh units.
        background: grey level of the empty pixels (1 = white).
        distance: camera distance from the origin.

    Returns:
        ``(V, size, size, 3) uint8``.
    """
    dirs = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    dirs = dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
    gb = render_gbuffer(mesh, RenderConfig(size=size, extent=extent, distance=distance, shadings=("smooth",)),
                        shading="smooth", normalise=False, directions=dirs)
    img = apply_styles(gb.normals, gb.mask, [style], background=background)[0]  # (V, 3, S, S)
    return (img.clamp(0, 1) * 255).round().byte().permute(0, 2, 3, 1).numpy()
