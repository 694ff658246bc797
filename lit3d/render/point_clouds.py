"""Point clouds as points: loading (PLY ASCII/binary, zipped PLY, ``.xyz``), colour, PCA normals, spacing.

Point clouds are rendered natively (:mod:`lit3d.render.splat`), not meshed. This module
is the loading and local-geometry half:

- :func:`load_points` reads (and sorts into a canonical order) ``.ply`` (ASCII with any property order, or binary through
  trimesh), a ``.zip`` holding one ``.ply`` (the CPCD2 layout), ``.xyz/.pts/.txt`` text,
  an ``(N, 3)``/``(N, 6)`` array or a ``trimesh.PointCloud`` into a :class:`PointShape`;
- :func:`is_point_source` says whether an input is a point cloud (a PLY without faces
  is one);
- :func:`local_frames` gives per-point PCA normals at two scales (``flat``: 8
  neighbours, ``smooth``: 16) and the local spacing (mean distance to the 6 nearest
  neighbours), from one SciPy KD-tree query; the smallest eigenvector of each 3x3
  covariance in closed form (:func:`smallest_eigenvector`, vectorised; ``numpy.linalg.eigh``
  of 370k matrices takes 2 s here).

Problems raise :class:`lit3d.render.convert.ShapeError` with one line naming the file.
"""
from __future__ import annotations

import hashlib
import io
import os
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from lit3d.render.convert import POINT_SUFFIXES, ShapeError, _name, check_shape_file

K_FLAT, K_SMOOTH, K_SPACING = 8, 16, 6


@dataclass
class PointShape:
    """A point cloud.

    Attributes:
        points: ``(N, 3) float64`` positions (file units).
        colours: ``(N, 3) float32`` RGB in ``[0, 1]``, or ``None`` (colour-less).
        label: name used in messages (the path).
    """

    points: np.ndarray
    colours: np.ndarray | None = None
    label: str = "<points>"

    def content_hash(self) -> str:
        """SHA-256 of positions and colours (cache key)."""
        h = hashlib.sha256(b"points")
        h.update(np.ascontiguousarray(self.points, dtype=np.float64).tobytes())
        if self.colours is not None:
            h.update(np.ascontiguousarray(self.colours, dtype=np.float32).tobytes())
        return h.hexdigest()


def _ply_header(head: bytes, label: str) -> tuple[str, list[tuple[str, int, list[str]]], int]:
    """(format, [(element, count, property names)], header byte length) of a PLY file."""
    end = head.find(b"end_header")
    if not head.startswith(b"ply") or end < 0:
        raise ShapeError(f"{label}: not a PLY file (no 'ply' magic or no end_header)")
    nl = head.find(b"\n", end)
    lines = head[:end].decode("ascii", "replace").splitlines()
    fmt, elements = "", []
    for ln in lines:
        tok = ln.split()
        if not tok:
            continue
        if tok[0] == "format" and len(tok) > 1:
            fmt = tok[1]
        elif tok[0] == "element" and len(tok) == 3:
            try:
                elements.append((tok[1], int(tok[2]), []))
            except ValueError as exc:
                raise ShapeError(f"{label}: bad PLY element line '{ln.strip()}'") from exc
        elif tok[0] == "property" and elements:
            elements[-1][2].append(tok[-1])
    return fmt, elements, (nl + 1 if nl >= 0 else len(head))


PLY_INT_MAX = {"uchar": 255, "uint8": 255, "char": 127, "int8": 127, "ushort": 65535, "uint16": 65535,
               "short": 32767, "int16": 32767}
PLY_FLOAT = ("float", "float32", "double", "float64")


def _vertex_types(head: bytes) -> dict[str, str]:
    """Declared types of the PLY ``vertex`` element's properties (``red`` -> ``uchar``)."""
    types: dict[str, str] = {}
    element = ""
    for ln in head[:head.find(b"end_header")].decode("ascii", "replace").splitlines():
        tok = ln.split()
        if len(tok) >= 2 and tok[0] == "element":
            element = tok[1]
        elif element == "vertex" and len(tok) == 3 and tok[0] == "property":
            types[tok[2]] = tok[1]
    return types


def _ply_colours(cols: np.ndarray, kind: str, label: str) -> np.ndarray:
    """``(N, 3)`` PLY colour values of declared type ``kind`` -> RGB in [0, 1]: integers are
    divided by their type's maximum (uchar: 255), floats are taken as [0, 1] already."""
    cols = np.asarray(cols, np.float64)
    bad = ~np.isfinite(cols)
    if bad.any():
        raise ShapeError(f"{label}: {int(bad.any(1).sum())} points have NaN or inf colours")
    if kind in PLY_FLOAT:
        if cols.size and (cols.min() < 0 or cols.max() > 1):
            raise ShapeError(f"{label}: float colours must lie in [0, 1] (found {cols.min():.4g} .. "
                             f"{cols.max():.4g}); write 0-255 colours as uchar")
        return cols.astype(np.float32)
    return (cols / PLY_INT_MAX.get(kind, 255)).astype(np.float32)


def read_ply_points(data: bytes, label: str) -> PointShape:
    """A point-only PLY (bytes) -> :class:`PointShape` (ASCII parsed here, binary via trimesh)."""
    fmt, elements, start = _ply_header(data[:65536], label)
    faces = [c for e, c, _ in elements if e == "face"]
    if faces and faces[0] > 0:
        raise ShapeError(f"{label}: PLY has {faces[0]} faces; it is a mesh, not a point cloud")
    vert = [(c, props) for e, c, props in elements if e == "vertex"]
    if not vert or vert[0][0] == 0:
        raise ShapeError(f"{label}: PLY has no vertices")
    n, props = vert[0]
    if not {"x", "y", "z"} <= set(props):
        raise ShapeError(f"{label}: PLY vertex has no x, y, z properties (has {', '.join(props)})")
    if fmt != "ascii":
        import trimesh

        try:
            pc = trimesh.load(io.BytesIO(data), file_type="ply", process=False)
        except Exception as exc:
            raise ShapeError(f"{label}: unreadable ply file ({type(exc).__name__}: {exc})") from exc
        # colours from the file's own values and declared type (trimesh turns floats into uint8,
        # NaN into 0); the positions from trimesh
        raw = (getattr(pc, "metadata", {}) or {}).get("_ply_raw", {}).get("vertex", {}).get("data")
        names = raw.dtype.names if raw is not None and raw.dtype.names else ()
        col = None
        if {"red", "green", "blue"} <= set(names) and len(raw) == len(pc.vertices):
            col = _ply_colours(np.stack([raw[c].ravel() for c in ("red", "green", "blue")], 1),
                               _vertex_types(data[:65536]).get("red", "uchar"), label)
        return _checked(np.asarray(pc.vertices, np.float64), col, label)
    try:
        vals = np.loadtxt(io.BytesIO(data[start:]), dtype=np.float64, max_rows=n, ndmin=2)
    except Exception as exc:
        raise ShapeError(f"{label}: unreadable ASCII PLY body ({type(exc).__name__}: {str(exc)[:80]})") from exc
    if vals.shape != (n, len(props)):
        raise ShapeError(f"{label}: PLY header declares {n} vertices of {len(props)} properties, "
                         f"body has {vals.shape[0]} rows of {vals.shape[1] if vals.ndim == 2 else 0}")
    col_idx = [props.index(c) for c in ("red", "green", "blue") if c in props]
    pts = vals[:, [props.index(c) for c in "xyz"]]
    colours = (_ply_colours(vals[:, col_idx], _vertex_types(data[:65536]).get("red", "uchar"), label)
               if len(col_idx) == 3 else None)
    return _checked(pts, colours, label)


def _checked(points: np.ndarray, colours: np.ndarray | None, label: str) -> PointShape:
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3 or len(p) == 0:
        raise ShapeError(f"{label}: expected (N, 3) points, got shape {tuple(p.shape)}")
    if not np.isfinite(p).all():
        raise ShapeError(f"{label}: points contain NaN or inf")
    if colours is not None and not np.isfinite(np.asarray(colours, np.float64)).all():
        raise ShapeError(f"{label}: colours contain NaN or inf")
    ext = float(np.ptp(p, axis=0).max())
    if len(p) < 4 or ext <= 0:
        raise ShapeError(f"{label}: degenerate point cloud ({len(p)} points, extent {ext:.3g})")
    # canonical (lexicographic) order: the renders, normals and cache key are functions of the
    # point set, not of the file's point order (a KD-tree breaks distance ties on a voxel lattice
    # by index, and the z-buffer breaks depth ties by index)
    order = np.lexsort((p[:, 2], p[:, 1], p[:, 0]))
    p = p[order]
    if colours is not None:
        colours = np.clip(np.asarray(colours, np.float32), 0.0, 1.0)[order]
    return PointShape(p, colours, label)


def _zip_ply(path: Path, label: str) -> bytes:
    try:
        with zipfile.ZipFile(path) as z:
            names = [n for n in z.namelist() if n.lower().endswith(".ply") and not n.endswith("/")]
            if len(names) != 1:
                raise ShapeError(f"{label}: zip holds {len(names)} .ply files, expected exactly one")
            return z.read(names[0])
    except zipfile.BadZipFile as exc:
        raise ShapeError(f"{label}: not a readable zip file ({exc})") from exc


def _has_faces(path: Path) -> bool:
    with open(path, "rb") as f:
        head = f.read(4096)
    try:
        _, elements, _ = _ply_header(head, str(path))
    except ShapeError:
        return True  # let the mesh loader report it
    return any(e == "face" and c > 0 for e, c, _ in elements)


def is_point_source(src: Any) -> bool:
    """True for point-cloud inputs: ``.zip``, ``.xyz/.pts/.txt``, a PLY without faces, a
    :class:`PointShape`, a ``trimesh.PointCloud`` or an ``(N, 3)``/``(N, 6)`` numpy array."""
    if isinstance(src, PointShape):
        return True
    if isinstance(src, (str, os.PathLike)):
        p = Path(src)
        suf = p.suffix.lower()
        if suf == ".zip" or suf in POINT_SUFFIXES:
            return True
        return suf == ".ply" and p.is_file() and p.stat().st_size > 0 and not _has_faces(p)
    if isinstance(src, np.ndarray):
        return src.ndim == 2 and src.shape[1] in (3, 6)
    return type(src).__name__ == "PointCloud"


def load_points(src: Any, name: str | None = None) -> PointShape:
    """Read any point input of :func:`is_point_source` into a validated :class:`PointShape`.

    Colours: PLY ``red/green/blue`` by their declared type (uchar 0..255, ushort 0..65535,
    float 0..1; any order; NaN refused), columns 4..6 of an ``(N, 6)`` array or text file
    (0..255), ``trimesh.PointCloud.colors``.
    """
    label = name or _name(src)
    if isinstance(src, PointShape):  # validated and put in canonical order
        return _checked(src.points, src.colours, src.label if name is None else label)
    if isinstance(src, (str, os.PathLike)):
        path = Path(src)
        check_shape_file(path, label)
        suf = path.suffix.lower()
        if suf == ".zip":
            return read_ply_points(_zip_ply(path, label), label)
        if suf == ".ply":
            return read_ply_points(path.read_bytes(), label)
        try:
            arr = np.loadtxt(path, ndmin=2, dtype=np.float64)
        except Exception as exc:
            raise ShapeError(f"{label}: unreadable point file ({type(exc).__name__}: {exc})") from exc
        src = arr
    if isinstance(src, np.ndarray):
        arr = np.asarray(src, dtype=np.float64)
        col = arr[:, 3:6] / 255.0 if arr.ndim == 2 and arr.shape[1] >= 6 else None
        return _checked(arr[:, :3] if arr.ndim == 2 and arr.shape[1] >= 3 else arr, col, label)
    col = getattr(src, "colors", None)
    col = np.asarray(col, np.float32)[:, :3] / 255.0 if col is not None and len(col) else None
    return _checked(np.asarray(src.vertices), col, label)


def local_frames(points: np.ndarray, workers: int = -1) -> dict[str, np.ndarray]:
    """PCA normals and spacing of a point cloud from one KD-tree query of ``K_SMOOTH`` neighbours.

    Args:
        points: ``(N, 3) float`` positions.
        workers: SciPy query threads (-1: all).

    Returns:
        ``{"flat": (N, 3) float32, "smooth": (N, 3) float32}`` unit normals (sign arbitrary:
        the renderer turns each towards its camera) from the ``K_FLAT`` / ``K_SMOOTH``
        nearest points (self included), and ``"spacing": (N,) float32``, the mean distance
        to the ``K_SPACING`` nearest other points.
    """
    from scipy.spatial import cKDTree

    p = np.asarray(points, dtype=np.float64)
    k = min(K_SMOOTH, len(p))
    dist, idx = cKDTree(p).query(p, k=k, workers=workers)
    out: dict[str, np.ndarray] = {"spacing": dist[:, 1:1 + K_SPACING].mean(1).astype(np.float32)}
    p32 = (p - p.mean(0)).astype(np.float32)
    # (N, k) offsets from the centre point, one coordinate at a time (gathering the columns is cheaper
    # than gathering (N, k, 3) rows and splitting them)
    cols = [np.ascontiguousarray(p32[:, i])[idx] - p32[:, i, None] for i in range(3)]
    for name, kk in (("flat", min(K_FLAT, k)), ("smooth", k)):
        out[name] = smallest_eigenvector(column_covariance([c if kk == k else np.ascontiguousarray(c[:, :kk])
                                                            for c in cols]))
    return out


def neighbour_covariance(x: np.ndarray) -> np.ndarray:
    """Scatter matrices ``(N, 3, 3) float64`` of ``(N, k, 3)`` neighbour offsets about their mean.

    The six distinct entries as row-wise dot products (``sum x_i x_j - k m_i m_j``): several
    times faster than a batched ``(3, k) @ (k, 3)`` matmul of 300k tiny matrices.
    """
    return column_covariance([np.ascontiguousarray(x[..., i]) for i in range(3)])


def column_covariance(cols: list[np.ndarray]) -> np.ndarray:
    """:func:`neighbour_covariance` of the offsets given as three contiguous ``(N, k)`` coordinate columns.

    The mean is summed over the ``k`` neighbours in order (as NumPy reduces the middle axis of ``(N, k, 3)``,
    so both forms give the same bits); the products in float64.
    """
    k = cols[0].shape[1]
    m = []
    for c in cols:
        total = c[:, 0].astype(np.float64)
        for j in range(1, k):
            total = total + c[:, j]
        m.append(total / k)
    out = np.empty((len(cols[0]), 3, 3), dtype=np.float64)
    for i in range(3):
        for j in range(i, 3):
            out[:, i, j] = np.einsum("nk,nk->n", cols[i], cols[j], dtype=np.float64) - k * m[i] * m[j]
            out[:, j, i] = out[:, i, j]
    return out


def smallest_eigenvalue(cov: np.ndarray, p_floor: float = 1e-300) -> np.ndarray:
    """Smallest eigenvalue ``(N,) float64`` of symmetric ``(N, 3, 3)`` matrices: the trigonometric solution of
    the characteristic cubic (``p_floor`` keeps isotropic matrices finite)."""
    a = np.asarray(cov, dtype=np.float64)
    a00, a01, a02, a11, a12, a22 = a[:, 0, 0], a[:, 0, 1], a[:, 0, 2], a[:, 1, 1], a[:, 1, 2], a[:, 2, 2]
    q = (a00 + a11 + a22) / 3.0
    b00, b11, b22 = a00 - q, a11 - q, a22 - q
    p = np.sqrt((b00 ** 2 + b11 ** 2 + b22 ** 2 + 2.0 * (a01 ** 2 + a02 ** 2 + a12 ** 2)) / 6.0)
    det = b00 * (b11 * b22 - a12 * a12) - a01 * (a01 * b22 - a12 * a02) + a02 * (a01 * a12 - b11 * a02)
    r = np.clip(det / np.maximum(p, p_floor) ** 3 / 2.0, -1.0, 1.0)
    return q + 2.0 * p * np.cos(np.arccos(r) / 3.0 + 2.0 * np.pi / 3.0)


def smallest_eigenvector(cov: np.ndarray) -> np.ndarray:
    """Unit eigenvector ``(N, 3) float32`` of the smallest eigenvalue of symmetric ``(N, 3, 3)`` matrices.

    Closed form: the eigenvalue from the trigonometric solution of the characteristic cubic,
    the vector as the longest cross product of two rows of ``A - lambda I`` (written out
    entry by entry: ``numpy.cross``/``det`` on 300k matrices cost more than the algebra).
    Isotropic neighbourhoods (all eigenvalues equal) give ``(0, 0, 1)``.
    """
    a = np.asarray(cov, dtype=np.float64)
    a00, a01, a02, a11, a12, a22 = a[:, 0, 0], a[:, 0, 1], a[:, 0, 2], a[:, 1, 1], a[:, 1, 2], a[:, 2, 2]
    lam = smallest_eigenvalue(a, p_floor=1e-30)
    m00, m11, m22 = a00 - lam, a11 - lam, a22 - lam  # rows (m00 a01 a02), (a01 m11 a12), (a02 a12 m22)
    cands = np.stack([
        np.stack([a01 * a12 - a02 * m11, a02 * a01 - m00 * a12, m00 * m11 - a01 * a01], 1),  # row0 x row1
        np.stack([a01 * m22 - a02 * a12, a02 * a02 - m00 * m22, m00 * a12 - a01 * a02], 1),  # row0 x row2
        np.stack([m11 * m22 - a12 * a12, a12 * a02 - a01 * m22, a01 * a12 - m11 * a02], 1),  # row1 x row2
    ], 1)
    norms2 = np.einsum("nij,nij->ni", cands, cands)
    best = norms2.argmax(1)
    rows = np.arange(len(a))
    vec = cands[rows, best]
    nrm = np.sqrt(norms2[rows, best])
    ok = nrm > 1e-12 * np.maximum(np.abs(a).reshape(len(a), -1).max(1), 1e-300)
    vec = np.where(ok[:, None], vec / np.where(ok, nrm, 1.0)[:, None], np.array([0.0, 0.0, 1.0]))
    return vec.astype(np.float32)
