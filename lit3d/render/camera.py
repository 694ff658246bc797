"""The one orthographic depth camera of lit3d: look-at placement, pyrender pass, linear depth.

Every depth image in lit3d comes from here: the canonical task's normalised depth
(:mod:`lit3d.render.depth`), the completion data's voxel-unit depth
(:mod:`datamodules.completion.depth_voxels`), the retrieval descriptor's views
(:mod:`lit3d.retrieval.descriptor`) and the quality G-buffer
(:mod:`lit3d.render.gbuffer`, which adds colour outputs to the same pass).

    cam = OrthoCamera(half_width=0.55, znear=0.5, zfar=3.5)
    dist, mask = render_ortho_depth(verts, faces, look_at([0, 0, 2]), 128, cam)   # (S, S) float64, bool

Depth is the camera distance along the view axis (``-z`` of the camera), 0 in the background.
"""
from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from lit3d.render.egl import import_pyrender, offscreen_renderer


def look_at(eye: np.ndarray, target: np.ndarray | None = None, up: np.ndarray | None = None,
            fallback_up: np.ndarray | None = None, parallel_cos: float = 0.999) -> np.ndarray:
    """OpenGL camera-to-world pose ``(4, 4) float64`` at ``eye`` looking at ``target``.

    The camera looks down its local ``-z`` axis with ``+y`` up (pyrender/OpenGL
    convention). ``up`` defaults to world ``+y``; when the view direction is parallel to
    it (``|cos| > parallel_cos``), ``fallback_up`` (default world ``+z``) is used instead.

    Args:
        eye: ``(3,)`` camera position.
        target: ``(3,)`` point looked at (default: the origin).
        up: ``(3,)`` unit up hint.
        fallback_up: ``(3,)`` unit up hint for views parallel to ``up``.
        parallel_cos: threshold on ``|cos(view, up)|`` above which ``fallback_up`` is used.
    """
    eye = np.asarray(eye, dtype=np.float64)
    target = np.zeros(3) if target is None else np.asarray(target, dtype=np.float64)
    up = np.array([0.0, 1.0, 0.0]) if up is None else np.asarray(up, dtype=np.float64)
    z = eye - target
    z = z / np.linalg.norm(z)
    if abs(float(np.dot(z, up))) > parallel_cos:
        up = np.array([0.0, 0.0, 1.0]) if fallback_up is None else np.asarray(fallback_up, dtype=np.float64)
    x = np.cross(up, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    pose = np.eye(4)
    pose[:3, 0], pose[:3, 1], pose[:3, 2], pose[:3, 3] = x, y, z, eye
    return pose


@dataclass(frozen=True)
class OrthoCamera:
    """An orthographic camera's projection.

    Attributes:
        half_width: half the visible width and height in world units (pyrender ``xmag = ymag``).
        znear: near clipping distance.
        zfar: far clipping distance.
    """

    half_width: float
    znear: float
    zfar: float

    def pyrender_camera(self):
        """The matching ``pyrender.OrthographicCamera``."""
        return import_pyrender().OrthographicCamera(xmag=self.half_width, ymag=self.half_width,
                                                    znear=self.znear, zfar=self.zfar)


def linear_depth_ortho(raw: np.ndarray, znear: float, zfar: float) -> np.ndarray:
    """Camera distance ``float64`` (shape of ``raw``) from pyrender's depth for an *orthographic* camera.

    pyrender linearises the depth buffer with the perspective formula for every camera;
    this inverts that and applies the orthographic (linear) mapping. Background (0) stays 0.
    """
    fg = raw > 0
    out = np.zeros(raw.shape, dtype=np.float64)
    ndc = (zfar + znear - 2 * znear * zfar / raw[fg].astype(np.float64)) / (zfar - znear)
    out[fg] = znear + (ndc + 1) / 2 * (zfar - znear)
    return out


def render_ortho(scene, poses: np.ndarray, size: int, camera: OrthoCamera, flags: int,
                 renderer=None) -> Iterator[tuple[np.ndarray | None, np.ndarray, np.ndarray]]:
    """Render ``scene`` from each camera-to-world pose with ``camera``; yields one view at a time.

    Args:
        scene: a ``pyrender.Scene`` holding the mesh (the camera is added and removed here).
        poses: ``(V, 4, 4)`` camera-to-world poses (see :func:`look_at`).
        size: square image side in pixels.
        camera: the projection.
        flags: ``pyrender.RenderFlags``; with ``DEPTH_ONLY`` no colour is returned.
        renderer: a ``pyrender.OffscreenRenderer`` of ``size`` (default: the shared cached one).

    Yields:
        ``(color, dist, mask)`` per view: ``(S, S, 3|4) uint8`` colour or ``None`` for depth-only
        passes, ``(S, S) float64`` camera distance (0 = background), ``(S, S) bool`` foreground.
    """
    renderer = offscreen_renderer(size, size) if renderer is None else renderer
    node = scene.add(camera.pyrender_camera(), pose=np.asarray(poses[0]))
    try:
        for pose in poses:
            scene.set_pose(node, np.asarray(pose))
            out = renderer.render(scene, flags=flags)
            color, raw = out if isinstance(out, tuple) else (None, out)
            raw = np.asarray(raw)
            yield color, linear_depth_ortho(raw, camera.znear, camera.zfar), raw > 0
    finally:
        scene.remove_node(node)


def render_ortho_depth(verts: np.ndarray, faces: np.ndarray, poses: np.ndarray, size: int, camera: OrthoCamera,
                       cull_faces: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Depth-only pass of a triangle mesh (flat normals, as uploaded by pyrender).

    Args:
        verts: ``(N, 3)`` vertex positions in world units.
        faces: ``(F, 3)`` int triangle indices.
        poses: ``(4, 4)`` one camera-to-world pose, or ``(V, 4, 4)`` several.
        size: square image side in pixels.
        camera: the projection.
        cull_faces: False sets ``RenderFlags.SKIP_CULL_FACES``; pyrender 0.1.45 ignores it in
            depth-only passes (back faces are always culled there).

    Returns:
        ``dist`` ``(S, S) float64`` camera distance (0 = background) and ``mask`` ``(S, S) bool``;
        ``(V, S, S)`` each when ``poses`` is ``(V, 4, 4)``.
    """
    import trimesh

    pyrender = import_pyrender()
    poses = np.asarray(poses, dtype=np.float64)
    single = poses.ndim == 2
    scene = pyrender.Scene()
    scene.add(pyrender.Mesh.from_trimesh(trimesh.Trimesh(verts, faces, process=False), smooth=False))
    flags = pyrender.RenderFlags.DEPTH_ONLY
    if not cull_faces:
        flags |= pyrender.RenderFlags.SKIP_CULL_FACES
    views = list(render_ortho(scene, poses[None] if single else poses, size, camera, flags))
    dist = np.stack([d for _, d, _ in views])
    mask = np.stack([m for _, _, m in views])
    return (dist[0], mask[0]) if single else (dist, mask)


def render_pinhole_depth(verts: np.ndarray, faces: np.ndarray, pose: np.ndarray, width: int, height: int,
                         fx: float, fy: float, cx: float, cy: float, znear: float, zfar: float,
                         cull_faces: bool = False) -> np.ndarray:
    """Depth-only pass of a triangle mesh through a pinhole (perspective) camera.

    Pixel ``(u, v)`` (column, row from the top) has its centre at image coordinates
    ``(u + 0.5, v + 0.5)``; a point at eye depth ``d`` (along the view axis) and camera-frame
    ``(x, y)`` (``x`` right, ``y`` up, OpenGL) lands at ``(fx x / d + cx, cy - fy y / d)``.

    Args:
        verts: ``(N, 3)`` vertex positions in world units.
        faces: ``(F, 3)`` int triangle indices.
        pose: ``(4, 4)`` camera-to-world pose (see :func:`look_at`).
        width, height: image size in pixels.
        fx, fy, cx, cy: intrinsics in pixels (principal point from the image's top-left corner).
        znear, zfar: clipping distances.
        cull_faces: False draws back faces too (open meshes stay closed to the camera).

    Returns:
        ``(H, W) float64`` eye depth along the view axis (z-depth; 0 = background). pyrender's
        perspective linearisation is exact for this camera.
    """
    import trimesh

    pyrender = import_pyrender()
    scene = pyrender.Scene()
    scene.add(pyrender.Mesh.from_trimesh(trimesh.Trimesh(verts, faces, process=False), smooth=False))
    scene.add(pyrender.IntrinsicsCamera(fx, fy, cx, cy, znear=znear, zfar=zfar), pose=np.asarray(pose, dtype=np.float64))
    flags = pyrender.RenderFlags.DEPTH_ONLY
    if not cull_faces:
        flags |= pyrender.RenderFlags.SKIP_CULL_FACES
    depth = offscreen_renderer(width, height).render(scene, flags=flags)
    return np.asarray(depth, dtype=np.float64)
