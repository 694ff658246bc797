"""G-buffer rasterisation with pyrender (EGL): view-space normals, depth and mask per view.

One unlit pass per view and shading replaces one lit render per style: the
mesh is uploaded once per shading with its world-space normals encoded as
vertex colours (``(n + 1) / 2``), rendered with ``RenderFlags.FLAT`` from the 12
dodecahedron cameras in one renderer session, and the colours are decoded and
rotated into each camera's frame in torch. Flat shading uses face normals
(vertices split per face), smooth shading area-weighted vertex normals.
Normals pass through the 8-bit colour buffer (about 0.004 per component).

The G-buffer renderer is a private ``OffscreenRenderer`` whose framebuffer has
single-sample storage (pyrender always allocates 4x MSAA): a multisampled
resolve would average the normal colours of an edge pixel with its neighbours
and the black background (wrong decoded normals along silhouettes and creases),
and on Mesa llvmpipe MSAA makes every pass about 3x slower.

Cameras are the one orthographic camera of :mod:`lit3d.render.camera`, looking at the
origin from ``distance``; the shape is
centred and scaled to a unit bounding box first, so it always fits in the
default half-width ``extent = 0.9`` (bounding sphere radius <= 0.866).
"""
from __future__ import annotations

import functools
from dataclasses import asdict, dataclass, field

import numpy as np
import torch

from lit3d.render.convert import normalise as normalise_mesh
from lit3d.render.camera import OrthoCamera, render_ortho
from lit3d.render.egl import import_pyrender, new_offscreen_renderer
from lit3d.render.dodecahedron import camera_poses, dodecahedron_directions

SHADINGS = ("flat", "smooth")


@dataclass(frozen=True)
class RenderConfig:
    """What determines the rendered pixels (part of the feature cache key).

    Attributes:
        size: square image side in pixels.
        extent: half-width of the orthographic view in normalised world units.
        distance: camera distance from the origin.
        shadings: which of ``"flat"``/``"smooth"`` to render.
    """

    size: int = 256
    extent: float = 0.9
    distance: float = 3.0
    shadings: tuple[str, ...] = field(default=SHADINGS)

    def as_dict(self) -> dict:
        d = asdict(self)
        d["shadings"] = list(self.shadings)
        return d


@dataclass
class GBuffer:
    """Per-view buffers of one mesh and shading.

    Attributes:
        normals: ``(V, 3, H, W) float32`` unit view-space normals (``+z`` towards the
            camera, ``+y`` up); 0 in the background.
        depth: ``(V, 1, H, W) float32`` camera distance along the view axis (orthographic
            linearisation of :func:`lit3d.render.camera.linear_depth_ortho`); 0 in the background.
        mask: ``(V, 1, H, W) bool`` foreground.
    """

    normals: torch.Tensor
    depth: torch.Tensor
    mask: torch.Tensor

    def to(self, device) -> "GBuffer":
        return GBuffer(self.normals.to(device), self.depth.to(device), self.mask.to(device))


def _pyrender_mesh(mesh, shading: str):
    pyrender = import_pyrender()
    v = np.asarray(mesh.vertices, dtype=np.float32)
    f = np.asarray(mesh.faces, dtype=np.int64)
    if shading == "flat":
        pos = v[f].reshape(-1, 3)
        nrm = np.repeat(np.asarray(mesh.face_normals, dtype=np.float32), 3, axis=0)
        idx = np.arange(len(pos), dtype=np.uint32).reshape(-1, 3)
    elif shading == "smooth":
        pos, idx = v, f.astype(np.uint32)
        nrm = np.asarray(mesh.vertex_normals, dtype=np.float32)
    else:
        raise ValueError(f"unknown shading {shading!r}; use one of {SHADINGS}")
    nrm = np.nan_to_num(nrm)
    col = np.concatenate([(nrm + 1.0) * 0.5, np.ones((len(nrm), 1), np.float32)], 1)
    mat = pyrender.MetallicRoughnessMaterial(baseColorFactor=[1.0, 1.0, 1.0, 1.0], doubleSided=True)
    prim = pyrender.Primitive(positions=pos, color_0=col, indices=idx, material=mat, mode=4)
    return pyrender.Mesh([prim])


@functools.cache
def _gbuffer_renderer(size: int):
    """A cached single-sample (no MSAA) offscreen renderer of ``size`` x ``size`` pixels.

    pyrender 0.1.45 hard-codes 4 samples in ``Renderer._configure_main_framebuffer``;
    we create the framebuffer eagerly while its storage call is redirected to 0 samples.
    Falls back to the shared (multisampled) renderer if pyrender's internals differ.
    """
    import_pyrender()
    import pyrender.renderer as prr

    renderer = new_offscreen_renderer(size, size)
    orig = getattr(prr, "glRenderbufferStorageMultisample", None)
    inner = getattr(renderer, "_renderer", None)
    platform = getattr(renderer, "_platform", None)
    if orig is None or inner is None or platform is None or not hasattr(inner, "_configure_main_framebuffer"):
        return renderer
    prr.glRenderbufferStorageMultisample = lambda target, samples, *a: orig(target, 0, *a)
    try:
        platform.make_current()
        inner.viewport_width, inner.viewport_height = size, size
        inner._configure_main_framebuffer()
    finally:
        prr.glRenderbufferStorageMultisample = orig
    return renderer


def render_gbuffers(mesh, config: RenderConfig | None = None, *, normalise: bool = True,
                    directions: np.ndarray | None = None) -> dict[str, GBuffer]:
    """Render every shading in ``config.shadings`` from every view in one renderer session.

    Args:
        mesh: ``trimesh.Trimesh`` (use :func:`lit3d.render.convert.to_mesh` first).
        config: image size, view extent and shadings.
        normalise: centre and scale the mesh to a unit bounding box first.
        directions: ``(V, 3)`` view directions (default: the 12 dodecahedron directions).

    Returns:
        ``{shading: GBuffer}`` with ``V`` views each.
    """
    pyrender = import_pyrender()
    cfg = config or RenderConfig()
    m = normalise_mesh(mesh) if normalise else mesh
    dirs = dodecahedron_directions() if directions is None else np.asarray(directions, dtype=np.float64)
    poses = camera_poses(cfg.distance, dirs)
    rot = torch.from_numpy(poses[:, :3, :3]).float()  # camera-to-world rotations (V, 3, 3)
    renderer = _gbuffer_renderer(cfg.size)
    scene = pyrender.Scene(bg_color=[0.0, 0.0, 0.0, 0.0], ambient_light=[1.0, 1.0, 1.0])
    camera = OrthoCamera(half_width=cfg.extent, znear=0.05, zfar=cfg.distance + 2.0)
    out: dict[str, GBuffer] = {}
    for shading in cfg.shadings:
        node = scene.add(_pyrender_mesh(m, shading))
        views = list(render_ortho(scene, poses, cfg.size, camera, pyrender.RenderFlags.FLAT, renderer))
        scene.remove_node(node)
        cols = [color[..., :3] for color, _, _ in views]
        col = torch.from_numpy(np.stack(cols)).float().permute(0, 3, 1, 2)  # (V, 3, H, W)
        dep = torch.from_numpy(np.stack([dist for _, dist, _ in views])).float()[:, None]
        mask = torch.from_numpy(np.stack([fg for _, _, fg in views]))[:, None]
        n_world = col * (2.0 / 255.0) - 1.0
        # view-space normal = R^T n_world  (R's columns are the camera axes in world space)
        n_view = torch.einsum("vji,vjhw->vihw", rot, n_world).contiguous()
        # normalise (F.normalize over dim 1 of this layout is ~30x slower on CPU)
        inv = (n_view * n_view).sum(1, keepdim=True).clamp_min(1e-24).rsqrt() * mask
        n_view = n_view * inv
        out[shading] = GBuffer(n_view.contiguous(), dep.contiguous(), mask.contiguous())
    return out


def render_gbuffer(mesh, config: RenderConfig | None = None, shading: str = "flat", **kw) -> GBuffer:
    """The G-buffer of one shading (see :func:`render_gbuffers`)."""
    cfg = config or RenderConfig()
    cfg = RenderConfig(cfg.size, cfg.extent, cfg.distance, (shading,))
    return render_gbuffers(mesh, cfg, **kw)[shading]
