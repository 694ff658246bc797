"""Pictures of voxel grids.

:func:`render_voxels`: shaded 3D renders (marching cubes -> the project's G-buffer pass ->
a MatCap style), what a person reads; used by the completion figures.
:func:`depth_shaded` / :func:`panel`: renderer-free depth-shaded projections along one grid
axis (near = bright), for quick previews (``lit3d-data`` show).

Grid axes (``datamodules.completion.depth_voxels``): index ``[i, j, k]`` is GL ``x = i`` (right),
``y = j`` (up), ``z = -k`` (``k = 0`` nearest the depth camera, which looks down GL ``-z``).
"""
from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F

from lit3d.render.convert import ShapeError, voxels_to_mesh
from lit3d.render.shaded import shaded_views

# GL directions from the shape towards the camera: front (the depth camera's side) and back,
# both from above and from the right/left, so the visible and the completed parts both show
FRONT_VIEW = (0.55, 0.45, 0.70)
BACK_VIEW = (-0.55, 0.45, -0.70)


def render_voxels(volume: torch.Tensor | np.ndarray, threshold: float = 0.5, size: int = 256,
                  directions=(FRONT_VIEW,), style: str = "clay_studio", extent: float = 0.78) -> np.ndarray:
    """Shaded renders of one grid: ``(V, size, size, 3) uint8``, white background.

    Args:
        volume: ``(D, D, D)`` occupancy or probabilities (any float/bool dtype); the surface is
            the marching-cubes level set at ``threshold`` (nearest-upsample coarse grids first
            with :func:`to_resolution` to show them as voxels next to finer ones).
        size: image side in pixels.
        directions: ``V`` GL view directions (shape -> camera), see :data:`FRONT_VIEW`.
        style: a MatCap style name of :mod:`lit3d.render.styles`.
        extent: orthographic half-width in units of the grid side (the grid cube spans
            [-0.5, 0.5]^3, so every grid of a figure is drawn at the same scale).
    An empty grid (nothing above ``threshold``) gives blank images.
    """
    vol = volume.detach().float().cpu().numpy() if isinstance(volume, torch.Tensor) else np.asarray(volume, np.float32)
    dirs = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    blank = np.full((len(dirs), size, size, 3), 255, np.uint8)
    try:
        mesh = voxels_to_mesh(vol, "<render_voxels>", level=threshold)
    except ShapeError:
        return blank
    d = vol.shape[0]
    # index space (+1 pad of voxels_to_mesh) -> GL, grid cube in [-0.5, 0.5]^3; z flipped
    t = np.diag([1.0 / d, 1.0 / d, -1.0 / d, 1.0])
    t[:3, 3] = [-(0.5 + 1.0 / d), -(0.5 + 1.0 / d), 0.5 + 1.0 / d]
    mesh.apply_transform(t)  # a reflection: trimesh flips the faces, normals stay outward
    return shaded_views(mesh, dirs, size, style, extent)


def depth_shaded(volume: torch.Tensor, threshold: float = 0.5, axis: int = 0) -> np.ndarray:
    """(D, H, W) occupancy or probabilities -> (H', W') uint8 image.

    Background is 0; occupied columns are shaded 255 (nearest) .. 70 (farthest).
    """
    occ = (volume.detach().float().cpu() >= threshold).movedim(axis, 0)
    d = occ.shape[0]
    hit = occ.any(0)
    first = torch.argmax(occ.to(torch.uint8), dim=0).float()
    shade = 255.0 - 185.0 * first / max(d - 1, 1)
    return torch.where(hit, shade, torch.zeros_like(shade)).to(torch.uint8).numpy()


def to_resolution(volume: torch.Tensor, size: int) -> torch.Tensor:
    """(D, H, W) grid -> (size, size, size) by nearest up/down-sampling."""
    v = volume.detach().float()[None, None]
    if v.shape[-1] == size:
        return v[0, 0]
    if v.shape[-1] > size:
        return F.adaptive_max_pool3d(v, size)[0, 0]
    return F.interpolate(v, size=(size,) * 3, mode="nearest")[0, 0]


def panel(volumes: list[torch.Tensor], threshold: float = 0.5, size: int | None = None, gap: int = 2) -> np.ndarray:
    """Side-by-side depth-shaded views of several (D, H, W) grids at one resolution -> uint8 (H, W)."""
    size = size or max(int(v.shape[-1]) for v in volumes)
    tiles = [depth_shaded(to_resolution(v, size), threshold) for v in volumes]
    sep = np.full((size, gap), 40, dtype=np.uint8)
    row: list[np.ndarray] = []
    for t in tiles:
        row.extend([t, sep])
    return np.concatenate(row[:-1], axis=1)
