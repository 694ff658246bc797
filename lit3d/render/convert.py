"""One step from any shape representation to a triangle mesh: :func:`to_mesh`.

The renderer and the mesh measures only see ``trimesh.Trimesh`` objects. Inputs:

- triangle meshes: ``.obj .off .ply .stl .glb .gltf`` (trimesh readers; scenes are
  concatenated);
- point clouds: ``.xyz .pts .txt`` (``N x 3`` text), a ``.ply`` without faces, an
  ``(N, 3)`` array, a ``trimesh.PointCloud`` — meshed by splatting the points into
  an occupancy grid, closing it and running marching cubes;
- voxel grids: ``.npz``/``.npy`` holding a 3-D (or ``(D, H, W, 1)``) array of
  ``{0, 1}`` (bool/int) or probabilities in ``[0, 1]`` — marching cubes at 0.5
  (scikit-image); packed bits as ``{"bits"|"packed": uint8, "shape": (3,)}``;
- SDF grids: a float grid with both signs, or any ``.npz`` key named ``sdf`` — the
  zero level set (negative inside).

Any problem raises :class:`ShapeError` with one line that names the file and what
is wrong (missing, a directory, empty file, unreadable, no faces, NaN vertices,
degenerate geometry, no surface in the grid).
"""
from __future__ import annotations

import hashlib
import os
from pathlib import Path
from typing import Any

import numpy as np

from lit3d.geometry.normalise import normalise_vertices
from lit3d.utils.errors import Lit3dError
from lit3d.utils.files import path_problem

MESH_SUFFIXES = {".obj", ".off", ".ply", ".stl", ".glb", ".gltf"}
POINT_SUFFIXES = {".xyz", ".pts", ".txt"}
GRID_SUFFIXES = {".npz", ".npy"}


class ShapeError(Lit3dError, ValueError):
    """A shape input that cannot be turned into a usable mesh (message names the file)."""


def _name(src: Any) -> str:
    return str(src) if isinstance(src, (str, os.PathLike)) else f"<{type(src).__name__}>"


def to_mesh(src: Any, *, name: str | None = None, point_resolution: int = 96):
    """Convert ``src`` (path or in-memory shape) to a validated ``trimesh.Trimesh``.

    Args:
        src: a path (see the module doc for formats), a ``trimesh.Trimesh``,
            ``trimesh.Scene``, ``trimesh.PointCloud``, an ``(N, 3)`` point array or a
            3-D grid array (numpy or torch).
        name: label used in error messages (defaults to the path).
        point_resolution: occupancy grid size used to mesh point clouds.

    Returns:
        A ``trimesh.Trimesh`` with finite vertices, at least one face and non-zero
        area (not yet normalised: see :func:`normalise`).

    Raises:
        ShapeError: one line naming the input and what is wrong.
    """
    import trimesh

    label = name or _name(src)
    if isinstance(src, (str, os.PathLike)):
        obj = _load_path(Path(src), label, point_resolution)
    else:
        obj = src
        if hasattr(obj, "detach") and hasattr(obj, "cpu"):  # torch tensor
            obj = obj.detach().cpu().numpy()
        if isinstance(obj, trimesh.Scene):
            obj = _scene_to_mesh(obj, label)
        if isinstance(obj, trimesh.PointCloud):
            obj = points_to_mesh(np.asarray(obj.vertices), label, point_resolution)
        elif isinstance(obj, np.ndarray):
            obj = _array_to_mesh(obj, label, point_resolution)
        elif not isinstance(obj, trimesh.Trimesh):
            raise ShapeError(f"{label}: unsupported shape type {type(obj).__name__}")
    return validate_mesh(obj, label)


def validate_mesh(mesh, label: str):
    """Check a ``trimesh.Trimesh`` for faces, finite vertices and non-zero size; return it."""
    v = np.asarray(mesh.vertices)
    f = np.asarray(mesh.faces)
    if v.size and not np.isfinite(v).all():
        raise ShapeError(f"{label}: vertices contain NaN or inf")
    if len(f) == 0:
        raise ShapeError(f"{label}: mesh has no faces ({len(v)} vertices)")
    if f.min() < 0 or f.max() >= len(v):
        raise ShapeError(f"{label}: face indices out of range (a face names vertex {int(f.max()) + 1} "
                         f"of {len(v)})")
    used = v[np.unique(f)]
    if np.ptp(used, axis=0).max() <= 0:
        raise ShapeError(f"{label}: degenerate mesh (all vertices identical: zero-size bounding box)")
    if not float(mesh.area) > 0:
        raise ShapeError(f"{label}: degenerate mesh (zero surface area)")
    return mesh


def normalise(mesh):
    """Copy of ``mesh`` centred at its bounding-box centre and scaled to unit longest side."""
    m = mesh.copy()
    m.vertices = normalise_vertices(m.vertices)[0]
    return m


def mesh_hash(mesh) -> str:
    """SHA-256 of a mesh's vertex and face arrays (content hash used as a cache key)."""
    h = hashlib.sha256()
    h.update(np.ascontiguousarray(mesh.vertices, dtype=np.float64).tobytes())
    h.update(np.ascontiguousarray(mesh.faces, dtype=np.int64).tobytes())
    return h.hexdigest()


# ------------------------------------------------------------------ loaders
def check_shape_file(path: Path, label: str) -> None:
    """Raise :class:`ShapeError` naming ``label`` when ``path`` is missing, a folder, a FIFO or device
    (never opened), in the wording of every command (:func:`lit3d.utils.files.path_problem`), or empty."""
    problem = path_problem(path)
    if problem is not None:
        raise ShapeError(f"{label}: {problem}")
    if path.stat().st_size == 0:
        raise ShapeError(f"{label}: empty file")


def _load_path(path: Path, label: str, point_resolution: int):
    import trimesh

    check_shape_file(path, label)
    suffix = path.suffix.lower()
    if suffix in GRID_SUFFIXES:
        return _array_to_mesh(_load_array(path, label), label, point_resolution)
    if suffix in POINT_SUFFIXES:
        try:
            pts = np.loadtxt(path, ndmin=2, dtype=np.float64)
        except Exception as exc:
            raise ShapeError(f"{label}: unreadable point file ({type(exc).__name__}: {exc})") from exc
        return points_to_mesh(pts[:, :3] if pts.shape[1] >= 3 else pts, label, point_resolution)
    if suffix not in MESH_SUFFIXES:
        raise ShapeError(f"{label}: unknown shape format '{suffix}' "
                         f"(use {' '.join(sorted(MESH_SUFFIXES | POINT_SUFFIXES | GRID_SUFFIXES))})")
    try:
        loaded = trimesh.load(str(path), force=None, process=False)
    except IndexError as exc:  # trimesh's OBJ reader indexes the vertex list with the face indices
        raise ShapeError(f"{label}: face indices out of range ({exc})") from exc
    except Exception as exc:
        msg = str(exc).splitlines()[0] if str(exc) else ""
        raise ShapeError(f"{label}: unreadable {suffix[1:]} file ({type(exc).__name__}: {msg})") from exc
    if isinstance(loaded, trimesh.Scene):
        loaded = _scene_to_mesh(loaded, label)
    if isinstance(loaded, trimesh.PointCloud):
        if len(loaded.vertices) == 0:
            raise ShapeError(f"{label}: no geometry in file")
        if suffix != ".ply":  # a point-only PLY is a point cloud; other mesh formats need faces
            raise ShapeError(f"{label}: mesh has no faces ({len(loaded.vertices)} vertices)")
        return points_to_mesh(np.asarray(loaded.vertices), label, point_resolution)
    if not isinstance(loaded, trimesh.Trimesh):
        raise ShapeError(f"{label}: unsupported content {type(loaded).__name__}")
    if len(loaded.faces) == 0 and len(loaded.vertices) == 0:
        raise ShapeError(f"{label}: no geometry in file (unreadable or empty {suffix[1:]})")
    if suffix == ".stl":  # a triangle soup (3 own vertices per face): shared like OBJ's, so smooth shading is smooth
        loaded.merge_vertices()
    return loaded


def _scene_to_mesh(scene, label: str):
    import trimesh

    geoms = [g for g in scene.dump() if isinstance(g, trimesh.Trimesh) and len(g.faces)]
    if geoms:
        return trimesh.util.concatenate(geoms)
    clouds = [g for g in scene.dump() if isinstance(g, trimesh.PointCloud) and len(g.vertices)]
    if clouds:
        return trimesh.PointCloud(np.concatenate([c.vertices for c in clouds]))
    raise ShapeError(f"{label}: no geometry in file (unreadable or empty)")


def load_array(path: str | os.PathLike, label: str | None = None) -> np.ndarray:
    """The array of a ``.npy``/``.npz`` shape file, read as :func:`to_mesh` reads it (npz keys
    ``bits``/``packed`` + ``shape`` unpacked, ``sdf``, ``voxels``, ``occupancy``, ``points``,
    ``arr_0``, else the first); an SDF grid comes back marked (:func:`is_sdf`). Raises
    :class:`ShapeError` naming ``label`` (default the path): missing, empty, unreadable."""
    p = Path(path)
    label = label or str(p)
    check_shape_file(p, label)
    return _load_array(p, label)


def is_sdf(arr: np.ndarray) -> bool:
    """True for a grid :func:`load_array` read from an npz key ``sdf`` (negative inside)."""
    return isinstance(arr, _SDF)


def _load_array(path: Path, label: str) -> np.ndarray:
    try:
        if path.suffix.lower() == ".npy":
            return np.load(path, allow_pickle=False)
        with np.load(path, allow_pickle=False) as z:
            keys = list(z.keys())
            if not keys:
                raise ShapeError(f"{label}: npz file holds no arrays")
            for k in ("bits", "packed"):
                if k in z and "shape" in z:
                    shape = tuple(int(s) for s in z["shape"])
                    n = int(np.prod(shape))
                    return np.unpackbits(z[k].ravel(), count=n).reshape(shape).astype(bool)
            if "sdf" in z:
                return _SDF(z["sdf"])
            for k in ("voxels", "occupancy", "points", "arr_0"):
                if k in z:
                    return z[k]
            return z[keys[0]]
    except ShapeError:
        raise
    except Exception as exc:
        raise ShapeError(f"{label}: unreadable array file ({type(exc).__name__}: {exc})") from exc


class _SDF(np.ndarray):
    """Marker subclass: this grid is a signed distance field (zero level set)."""

    def __new__(cls, arr):
        return np.asarray(arr).view(cls)


def _array_to_mesh(arr: np.ndarray, label: str, point_resolution: int):
    is_sdf = isinstance(arr, _SDF)
    arr = np.asarray(arr)
    if arr.size == 0:
        raise ShapeError(f"{label}: empty array")
    if arr.dtype.kind not in "biuf":  # strings, complex, objects: not a grid or points
        raise ShapeError(f"{label}: array has dtype {arr.dtype}, expected bool, integer or float values")
    if arr.ndim == 2 and arr.shape[1] == 3 and not is_sdf:
        return points_to_mesh(arr.astype(np.float64), label, point_resolution)
    if arr.ndim == 4 and arr.shape[-1] == 1:
        arr = arr[..., 0]
    if arr.ndim == 4 and arr.shape[0] == 1:
        arr = arr[0]
    if arr.ndim != 3:
        raise ShapeError(f"{label}: expected a 3-D grid or (N, 3) points, got shape {tuple(arr.shape)}")
    if not np.isfinite(arr.astype(np.float64, copy=False)).all():
        raise ShapeError(f"{label}: grid contains NaN or inf")
    if not is_sdf and arr.dtype.kind == "f" and arr.min() < 0:
        is_sdf = True
    return sdf_to_mesh(arr, label) if is_sdf else voxels_to_mesh(arr, label)


def voxels_to_mesh(grid: np.ndarray, label: str = "<grid>", level: float = 0.5):
    """Marching cubes (scikit-image) of an occupancy grid ``(D, H, W)`` at ``level``.

    The grid is padded with one empty voxel so the surface is closed; vertices are
    in voxel units (normalise afterwards).
    """
    g = np.asarray(grid, dtype=np.float32)
    if not (g > level).any():
        raise ShapeError(f"{label}: voxel grid is empty (no cell above {level})")
    return _marching_cubes(np.pad(g, 1, constant_values=0.0), level, label)


def sdf_to_mesh(sdf: np.ndarray, label: str = "<grid>", level: float = 0.0):
    """Zero level set (negative inside) of a signed distance grid ``(D, H, W)``."""
    s = np.asarray(sdf, dtype=np.float32)
    if not (s.min() < level < s.max()):
        raise ShapeError(f"{label}: SDF grid has no zero crossing (range {s.min():.3g}..{s.max():.3g})")
    big = float(max(s.max(), 1.0))
    return _marching_cubes(np.pad(s, 1, constant_values=big), level, label, flip=True)


def _marching_cubes(vol: np.ndarray, level: float, label: str, flip: bool = False):
    """skimage marching cubes; faces wound so normals point out of the object."""
    import trimesh
    from skimage import measure

    try:
        verts, faces, _, _ = measure.marching_cubes(vol, level=level,
                                                    gradient_direction="ascent" if flip else "descent")
    except (ValueError, RuntimeError) as exc:
        raise ShapeError(f"{label}: no surface in grid ({exc})") from exc
    mesh = trimesh.Trimesh(verts.astype(np.float64), faces.astype(np.int64), process=False)
    if mesh.volume < 0:  # closed surface wound inwards: flip to outward normals
        mesh.invert()
    return mesh


def points_to_mesh(points: np.ndarray, label: str = "<points>", resolution: int = 96):
    """Mesh a point cloud ``(N, 3)``: splat into an occupancy grid, close, fill, marching cubes."""
    from scipy import ndimage

    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3 or len(p) == 0:
        raise ShapeError(f"{label}: expected (N, 3) points, got shape {tuple(p.shape)}")
    if not np.isfinite(p).all():
        raise ShapeError(f"{label}: points contain NaN or inf")
    lo, hi = p.min(0), p.max(0)
    ext = float((hi - lo).max())
    if len(p) < 4 or ext <= 0:
        raise ShapeError(f"{label}: degenerate point cloud ({len(p)} points, extent {ext:.3g})")
    from scipy.spatial import cKDTree

    r = resolution
    voxel = ext / (r - 8)
    spacing = float(np.median(cKDTree(p).query(p[: 20000], k=2)[0][:, 1]))
    k = int(np.clip(np.ceil(3.0 * spacing / voxel) + 1, 2, r // 8))  # close gaps between samples
    idx = np.clip(np.rint((p - (lo + hi) / 2) / voxel + r / 2).astype(int), 0, r - 1)
    occ = np.zeros((r, r, r), bool)
    occ[idx[:, 0], idx[:, 1], idx[:, 2]] = True
    occ = ndimage.binary_dilation(occ, iterations=k)
    occ = ndimage.binary_fill_holes(occ)
    occ = ndimage.binary_erosion(occ, iterations=k - 1)
    vol = ndimage.gaussian_filter(occ.astype(np.float32), 0.7)
    level = min(0.5, 0.5 * float(vol.max()))
    mesh = _marching_cubes(np.pad(vol, 1), level, label)
    mesh.apply_translation(-np.array([r / 2 + 1] * 3))
    mesh.apply_scale(voxel)
    mesh.apply_translation((lo + hi) / 2)
    return mesh
