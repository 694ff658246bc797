"""Native point rendering: splat a point cloud into the G-buffers the MatCap styles read.

No meshing: every point is a screen-aligned disc splat of its local spacing
(:func:`lit3d.render.point_clouds.local_frames`; radius ``SPLAT_SCALE x`` the mean distance
to its 8 nearest neighbours, at least its own pixel, at most ``MAX_RADIUS_PX``), seen
from the same 12 orthographic dodecahedron cameras as meshes
(:mod:`lit3d.render.dodecahedron`, half-width ``extent``, image row 0 at the top). Visibility
is a z-buffer in torch (:func:`nearest_splats`): each splat pixel carries the key
``depth * N + index`` and ``scatter_reduce(amin)`` keeps the nearest point, so the winner's PCA
normal, depth and colour fill the pixel. Shadings: ``flat`` uses normals from 8 neighbours,
``smooth`` from 16 (a wider, smoother PCA); each normal is turned to face its camera.

Both clouds of a pair are placed in one frame (:func:`point_frame` of the reference:
bounding-box centre at the origin, longest side 1), so a shift or scaling of the
distorted cloud is seen as such.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from lit3d.render.gbuffer import GBuffer, RenderConfig
from lit3d.render.point_clouds import PointShape, local_frames
from lit3d.render.dodecahedron import camera_poses, dodecahedron_directions

SPLAT_SCALE = 0.75
MAX_RADIUS_PX = 8
OUTLIER_SPACING = 2.0  # isolated points splat no larger than twice the cloud's median spacing
_DEPTH_BITS = 1 << 24


@dataclass
class PointGBuffer(GBuffer):
    """A :class:`GBuffer` of a point cloud plus the visible points' colours.

    Attributes:
        colour: ``(V, 3, H, W) float32`` RGB in ``[0, 1]`` (0 in the background), or ``None``.
    """

    colour: torch.Tensor | None = None

    def to(self, device) -> "PointGBuffer":
        c = None if self.colour is None else self.colour.to(device)
        return PointGBuffer(self.normals.to(device), self.depth.to(device), self.mask.to(device), c)


def point_frame(points: np.ndarray) -> tuple[np.ndarray, float]:
    """``(centre (3,), scale)``: bounding-box centre and ``1 / longest side`` of ``(N, 3)`` points."""
    p = np.asarray(points, dtype=np.float64)
    lo, hi = p.min(0), p.max(0)
    return (lo + hi) / 2.0, 1.0 / max(float((hi - lo).max()), 1e-12)


def _disc(r: int) -> torch.Tensor:
    """``(K, 2) int64`` pixel offsets ``(dy, dx)`` of a disc of integer radius ``r`` (``r = 0``: one pixel)."""
    t = torch.arange(-r, r + 1)
    dy, dx = torch.meshgrid(t, t, indexing="ij")
    keep = dy * dy + dx * dx <= r * r + r
    return torch.stack([dy[keep], dx[keep]], 1)


EMPTY = torch.iinfo(torch.int64).max  # z-buffer value of a pixel no splat covers


def nearest_splats(row: torch.Tensor, col: torch.Tensor, key: torch.Tensor, radius: torch.Tensor,
                   size: int) -> torch.Tensor:
    """Z-buffer ``(V, size * size) int64`` of disc splats: each pixel's smallest ``key`` among the splats covering
    it (:data:`EMPTY` where none does).

    Args:
        row, col: ``(V, N) int64`` pixel of each point's centre in each view (any value: off-image centres too).
        key: ``(V, N) int64`` per point and view (quantised depth x N + index: the nearest point wins).
        radius: ``(N,) int64`` disc radius of each point in pixels, ``0..MAX_RADIUS_PX`` (:func:`_disc`).
        size: image side.

    The splat pixels are scattered (``scatter_reduce`` ``amin``, which does not depend on the order) into
    each view's canvas grown by a margin of ``2 MAX_RADIUS_PX`` pixels, where the pixels of discs that reach
    the image but overhang it land (cropped off at the end), and discs that cannot reach the image go to a
    sink: no splat pixel needs a bounds test. The points are grouped by radius with one gather.
    """
    v, s = row.shape[0], int(size)
    pad = 2 * MAX_RADIUS_PX
    w = s + 2 * pad
    span = MAX_RADIUS_PX * (w + 1)  # largest |dy w + dx| of a disc offset
    buf = torch.full((v * w * w + 2 * span + 1,), EMPTY, dtype=torch.int64)
    sink = v * w * w + span
    vbase = (torch.arange(v) * (w * w) + pad * w + pad)[:, None]
    order = torch.argsort(radius, stable=True)
    counts = torch.bincount(radius, minlength=MAX_RADIUS_PX + 1).tolist()
    rows, cols, keys = (t.index_select(1, order) for t in (row, col, key))
    start = 0
    for r, cnt in enumerate(counts):
        if cnt == 0:
            continue
        rr, cc, kk = (t[:, start:start + cnt] for t in (rows, cols, keys))
        start += cnt
        near = (rr >= -r) & (rr < s + r) & (cc >= -r) & (cc < s + r)  # a disc of radius r reaching the image
        base = torch.where(near, vbase + rr * w + cc, sink).flatten()
        kk = kk.flatten()
        for dy, dx in _disc(r).tolist():
            buf.scatter_reduce_(0, base + (dy * w + dx), kk, "amin")
    return buf[:v * w * w].view(v, w, w)[:, pad:pad + s, pad:pad + s].reshape(v, s * s)


def render_point_gbuffers(shape: PointShape, config: RenderConfig | None = None, *,
                          frame: tuple[np.ndarray, float] | None = None,
                          frames: dict[str, np.ndarray] | None = None,
                          directions: np.ndarray | None = None) -> dict[str, PointGBuffer]:
    """Splat ``shape`` from every view for every shading in ``config.shadings``.

    Args:
        shape: the point cloud (colours optional).
        config: image size, view extent, camera distance, shadings.
        frame: ``(centre, scale)`` placing the cloud in normalised units (default: its own
            :func:`point_frame`).
        frames: :func:`local_frames` of ``shape.points`` if already computed.
        directions: ``(V, 3)`` view directions (default: the 12 dodecahedron directions).

    Returns:
        ``{shading: PointGBuffer}``: normals ``(V, 3, H, W)`` view space facing the camera,
        depth ``(V, 1, H, W)`` camera distance, mask ``(V, 1, H, W) bool``, colour
        ``(V, 3, H, W)`` or ``None``.
    """
    cfg = config or RenderConfig()
    centre, scale = point_frame(shape.points) if frame is None else frame
    lf = local_frames(shape.points) if frames is None else frames
    dirs = dodecahedron_directions() if directions is None else np.asarray(directions, dtype=np.float64)
    rot = torch.from_numpy(camera_poses(cfg.distance, dirs)[:, :3, :3]).float()  # (V, 3, 3) camera-to-world
    p = torch.from_numpy(((shape.points - centre) * scale).astype(np.float32))
    n, v, s, e = p.shape[0], rot.shape[0], cfg.size, float(cfg.extent)
    cam = torch.einsum("nj,vji->vni", p, rot)  # (V, N, 3) camera coordinates (+z towards the camera)
    col = ((cam[..., 0] + e) * (s / (2 * e))).floor().long()
    row = ((e - cam[..., 1]) * (s / (2 * e))).floor().long()
    depth = cfg.distance - cam[..., 2]
    dq = (depth / (cfg.distance + 2.0)).clamp(0, 1).mul(_DEPTH_BITS - 1).long()
    key = dq * n + torch.arange(n)[None]  # (V, N)
    spacing = np.minimum(lf["spacing"], OUTLIER_SPACING * float(np.median(lf["spacing"])))
    radius_px = torch.from_numpy(spacing * (SPLAT_SCALE * scale * s / (2 * e)))
    r_int = radius_px.round().clamp(0, MAX_RADIUS_PX).long()
    buf = nearest_splats(row, col, key, r_int, s).view(-1)
    mask = buf != EMPTY
    idx = torch.where(mask, buf % n, torch.zeros_like(buf)).view(v, s * s)
    mask = mask.view(v, s * s)
    dep = torch.where(mask, torch.gather(depth, 1, idx), torch.zeros(()))
    out: dict[str, PointGBuffer] = {}
    colour = None
    if shape.colours is not None:
        c = torch.from_numpy(np.asarray(shape.colours, np.float32))[idx] * mask[..., None]  # (V, H*W, 3)
        colour = c.view(v, s, s, 3).permute(0, 3, 1, 2).contiguous()
    m4 = mask.view(v, 1, s, s)
    for shading in cfg.shadings:
        if shading not in lf:
            raise ValueError(f"unknown shading {shading!r}; use one of ('flat', 'smooth')")
        nv = torch.bmm(torch.from_numpy(lf[shading])[idx], rot)  # (V, H*W, 3): R^T n per view
        nv = torch.where(nv[..., 2:3] < 0, -nv, nv) * mask[..., None]
        nv = nv.view(v, s, s, 3).permute(0, 3, 1, 2).contiguous()
        out[shading] = PointGBuffer(nv, dep.view(v, 1, s, s).clone(), m4.clone(), colour)
    return out
