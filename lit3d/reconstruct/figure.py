"""The labelled picture of one reconstruction (``S`` = 256 px panels by default)::
    input depth      | partial points: camera view | side view | back view
    object pixels    | completed shape: camera view | side view | back view

The partial points are splatted (z-buffered discs, shaded by depth); the completed mesh is a
shaded render (G-buffer normals + a MatCap style from :mod:`lit3d.render`). Both use the same
three orthographic views of the completed shape's bounding box, so they line up.
"""
from __future__ import annotations

import io

import numpy as np

from lit3d.utils.figures import font
from lit3d.render.dodecahedron import camera_poses

# view directions (towards the camera) in the GL frame of the input camera (x right, y up, z back)
VIEWS = {"camera view": (0.0, 0.0, 1.0), "side view": (1.0, 0.25, 0.15), "back view": (-0.35, 0.35, -1.0)}
STYLE = "basic_1"
LABEL_PX = 22


def depth_panel(depth: np.ndarray, keep: np.ndarray | None, size: int) -> np.ndarray:
    """``(size, size, 3) uint8``: depth (near = bright, background black), letterboxed; with
    ``keep`` the object pixels are tinted orange and the rest darkened."""
    from PIL import Image

    d = depth.astype(np.float64)
    fg = d > 0
    lo, hi = (d[fg].min(), d[fg].max()) if fg.any() else (0.0, 1.0)
    v = np.where(fg, 0.25 + 0.75 * (hi - d) / max(hi - lo, 1e-9), 0.0)
    rgb = np.repeat(v[..., None], 3, axis=2)
    if keep is not None:
        rgb = np.where(keep[..., None], rgb * np.array([1.0, 0.62, 0.25]) + np.array([0.0, 0.1, 0.05]), rgb * 0.35)
    img = Image.fromarray((rgb.clip(0, 1) * 255).astype(np.uint8))
    h, w = d.shape
    k = size / max(h, w)
    img = img.resize((max(1, round(w * k)), max(1, round(h * k))), Image.NEAREST)
    canvas = Image.new("RGB", (size, size))
    canvas.paste(img, ((size - img.width) // 2, (size - img.height) // 2))
    return np.asarray(canvas)


def _view_frames(directions: np.ndarray) -> np.ndarray:
    return camera_poses(3.0, directions)


def points_panels(points_gl: np.ndarray, directions: np.ndarray, size: int, extent: float = 0.9) -> list[np.ndarray]:
    """Splat normalised GL-frame points ``(N, 3)`` from each view: ``(size, size, 3) uint8`` each."""
    out = []
    radius = max(1, size // 128)
    for pose in _view_frames(directions):
        rot, eye = pose[:3, :3], pose[:3, 3]
        q = (points_gl - eye) @ rot  # view coordinates: x right, y up, -z forward
        px = ((q[:, 0] / extent + 1) / 2 * size).astype(int)
        py = ((1 - q[:, 1] / extent) / 2 * size).astype(int)
        z = -q[:, 2]
        zbuf = np.full((size, size), np.inf)
        for dy in range(-radius, radius + 1):
            for dx in range(-radius, radius + 1):
                x, y = px + dx, py + dy
                ok = (x >= 0) & (x < size) & (y >= 0) & (y < size)
                np.minimum.at(zbuf, (y[ok], x[ok]), z[ok])
        fg = np.isfinite(zbuf)
        img = np.zeros((size, size, 3))
        if fg.any():
            lo, hi = zbuf[fg].min(), zbuf[fg].max()
            shade = 1.0 - 0.6 * (zbuf - lo) / max(hi - lo, 1e-9)
            img[fg] = shade[fg, None] * np.array([0.35, 0.65, 1.0])
        out.append((img * 255).astype(np.uint8))
    return out


def mesh_panels(mesh_gl, directions: np.ndarray, size: int, extent: float = 0.9) -> list[np.ndarray]:
    """Shaded renders of a normalised GL-frame mesh from each view: ``(size, size, 3) uint8`` each."""
    from lit3d.render.shaded import shaded_views

    return list(shaded_views(mesh_gl, directions, size, STYLE, extent, background=0.0))


def _labelled(tile: np.ndarray, text: str):
    from PIL import Image, ImageDraw

    img = Image.new("RGB", (tile.shape[1], tile.shape[0] + LABEL_PX), (255, 255, 255))
    img.paste(Image.fromarray(tile), (0, LABEL_PX))
    ImageDraw.Draw(img).text((4, 3), text, fill=(0, 0, 0), font=font())
    return img


def figure_png(depth: np.ndarray, keep: np.ndarray, points: np.ndarray, mesh, title: str,
               size: int = 256) -> bytes:
    """PNG bytes of the labelled picture (see the module doc). ``points`` ``(N, 3)`` and ``mesh``
    are in the camera frame (metres); both are normalised by the mesh's bounding box."""
    from PIL import Image, ImageDraw

    flip = np.array([1.0, -1.0, -1.0])  # camera frame (y down, z forward) -> GL (y up, z back)
    m = mesh.copy()
    m.vertices = np.asarray(m.vertices) * flip
    lo, hi = m.bounds
    centre, scale = (lo + hi) / 2, 1.0 / float(max(hi - lo))
    m.vertices = (np.asarray(m.vertices) - centre) * scale
    if m.volume < 0:
        m.invert()
    pts = (points * flip - centre) * scale
    dirs = np.array([np.asarray(v) / np.linalg.norm(v) for v in VIEWS.values()])
    rows = [[_labelled(depth_panel(depth, None, size), "input depth")]
            + [_labelled(t, f"partial points: {n}") for t, n in zip(points_panels(pts, dirs, size), VIEWS)],
            [_labelled(depth_panel(depth, keep, size), "object pixels (orange)")]
            + [_labelled(t, f"completed: {n}") for t, n in zip(mesh_panels(m, dirs, size), VIEWS)]]
    tw, th = rows[0][0].size
    gap, head = 4, 26
    sheet = Image.new("RGB", (4 * tw + 3 * gap, head + 2 * th + gap), (255, 255, 255))
    ImageDraw.Draw(sheet).text((4, 5), title, fill=(0, 0, 0), font=font(16))
    for r, row in enumerate(rows):
        for c, tile in enumerate(row):
            sheet.paste(tile, (c * (tw + gap), head + r * (th + gap)))
    buf = io.BytesIO()
    sheet.save(buf, format="PNG")
    return buf.getvalue()
