"""TOSCA non-rigid shapes: ``.mat`` (struct ``surface`` with X, Y, Z, 1-based TRIV), ASCII ``.vert`` +
``.tri``, ``.off`` and ``.ply`` (the decimated copy in ../shared/data/tosca8k).

File names are ``<class><pose>.<ext>`` (``cat0.mat``, ``david13.off``); pose 0 is the null
(reference) pose. Pose indices have gaps (no dog4), so folders are globbed, never looped
over ranges. TOSCA's up axis is +z.

    items = index_tosca(root)               # [ToscaItem(cls, pose, path), ...]
    verts, faces = read_mesh(items[0].path)  # (V, 3) float64, (F, 3) int64 (0-based)
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lit3d.utils.errors import Lit3dError

TOSCA_CLASSES = ("cat", "centaur", "david", "dog", "gorilla", "horse", "michael", "victoria", "wolf")
EXTS = (".mat", ".vert", ".off", ".ply", ".obj")
_NAME = re.compile(r"^([A-Za-z_]+?)_?(\d+)$")


class MeshReadError(Lit3dError, ValueError):
    """A mesh file that cannot be used: the message names the file and the problem."""


@dataclass(frozen=True)
class ToscaItem:
    cls: str
    pose: int
    path: Path


def parse_name(path: str | Path) -> tuple[str, int]:
    """``david13.off`` -> ("david", 13). Raises MeshReadError when the stem has no pose number."""
    m = _NAME.match(Path(path).stem)
    if not m:
        raise MeshReadError(f"{path}: file name is not <class><pose number> (e.g. cat3.mat)")
    return m.group(1).lower(), int(m.group(2))


def _check(path, verts, faces) -> tuple[np.ndarray, np.ndarray]:
    verts = np.asarray(verts, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    if verts.ndim != 2 or verts.shape[1] != 3 or len(verts) == 0:
        raise MeshReadError(f"{path}: expected (V, 3) vertices, got shape {verts.shape}")
    if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) == 0:
        raise MeshReadError(f"{path}: expected (F, 3) triangles, got shape {faces.shape} (empty mesh?)")
    if not np.isfinite(verts).all():
        raise MeshReadError(f"{path}: vertices contain NaN or Inf")
    if faces.min() < 0 or faces.max() >= len(verts):
        raise MeshReadError(f"{path}: face index out of range [0, {len(verts)})")
    return verts, faces


def read_mat(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """TOSCA ``.mat``: struct ``surface`` with column vectors X, Y, Z and 1-based TRIV."""
    from scipy.io import loadmat

    try:
        data = loadmat(str(path), squeeze_me=True, struct_as_record=False)
    except Exception as exc:
        raise MeshReadError(f"{path}: not a readable .mat file ({exc})") from exc
    if "surface" not in data:
        raise MeshReadError(f"{path}: no 'surface' struct (found {sorted(k for k in data if not k.startswith('__'))})")
    s = data["surface"]
    try:
        verts = np.stack([np.ravel(s.X), np.ravel(s.Y), np.ravel(s.Z)], 1)
        faces = np.asarray(s.TRIV, dtype=np.int64) - 1
    except AttributeError as exc:
        raise MeshReadError(f"{path}: 'surface' lacks a field ({exc})") from exc
    return _check(path, verts, faces)


def read_vert_tri(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """ASCII ``.vert`` (x y z per line) + ``.tri`` beside it (1-based i j k per line)."""
    path = Path(path)
    vert, tri = path.with_suffix(".vert"), path.with_suffix(".tri")
    if not tri.is_file():
        raise MeshReadError(f"{vert}: no matching triangle file {tri.name}")
    try:
        verts = np.loadtxt(vert, ndmin=2)
        faces = np.loadtxt(tri, ndmin=2).astype(np.int64) - 1
    except ValueError as exc:
        raise MeshReadError(f"{path}: malformed .vert/.tri ({exc})") from exc
    return _check(vert, verts, faces)


def read_off(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """ASCII ``.off`` (polygons are fan-triangulated)."""
    tokens = []
    with open(path) as f:
        for line in f:
            line = line.split("#", 1)[0].strip()
            if line:
                tokens.append(line)
    if not tokens or not tokens[0].startswith("OFF"):
        raise MeshReadError(f"{path}: not an OFF file (first line must be OFF)")
    head = tokens[0][3:].split()
    body = tokens[1:]
    if not head:
        head, body = body[0].split(), body[1:]
    nv, nf = int(head[0]), int(head[1])
    if len(body) < nv + nf:
        raise MeshReadError(f"{path}: truncated OFF ({len(body)} lines for {nv} vertices + {nf} faces)")
    verts = np.array([[float(x) for x in body[i].split()[:3]] for i in range(nv)])
    faces = []
    for line in body[nv:nv + nf]:
        ids = [int(x) for x in line.split()]
        k, poly = ids[0], ids[1:ids[0] + 1]
        faces += [[poly[0], poly[i], poly[i + 1]] for i in range(1, k - 1)]
    return _check(path, verts, np.array(faces).reshape(-1, 3))


def read_trimesh(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """``.ply`` / ``.obj`` through trimesh (no processing: vertex order is kept)."""
    import trimesh

    try:
        m = trimesh.load(str(path), force="mesh", process=False)
    except Exception as exc:
        raise MeshReadError(f"{path}: unreadable mesh ({exc})") from exc
    return _check(path, m.vertices, m.faces)


def read_mesh(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Any supported TOSCA format -> ``(V, 3) float64``, ``(F, 3) int64`` 0-based."""
    path = Path(path)
    ext = path.suffix.lower()
    if not path.is_file():
        raise MeshReadError(f"{path}: file not found")
    if ext == ".mat":
        return read_mat(path)
    if ext in (".vert", ".tri"):
        return read_vert_tri(path)
    if ext == ".off":
        return read_off(path)
    if ext in (".ply", ".obj"):
        return read_trimesh(path)
    raise MeshReadError(f"{path}: unsupported mesh format '{ext}' (use {', '.join(EXTS)})")


def index_tosca(root: str | Path, classes: list[str] | None = None) -> list[ToscaItem]:
    """Glob ``root`` (recursively) for TOSCA meshes; one item per (class, pose), preferring
    .mat > .off > .ply > .vert when a shape exists in several formats. Sorted by (class, pose)."""
    root = Path(root)
    if not root.is_dir():
        raise MeshReadError(f"{root}: TOSCA folder not found")
    rank = {e: i for i, e in enumerate((".mat", ".off", ".ply", ".obj", ".vert"))}
    best: dict[tuple[str, int], Path] = {}
    for p in sorted(root.rglob("*")):
        ext = p.suffix.lower()
        if ext not in rank or not p.is_file():
            continue
        try:
            cls, pose = parse_name(p)
        except MeshReadError:
            continue
        if classes and cls not in classes:
            continue
        key = (cls, pose)
        if key not in best or rank[ext] < rank[best[key].suffix.lower()]:
            best[key] = p
    if not best:
        raise MeshReadError(f"{root}: no TOSCA meshes (<class><pose>.mat/.off/.ply/.vert) found")
    return [ToscaItem(c, k, best[(c, k)]) for c, k in sorted(best)]


def z_up_to_y_up(verts: np.ndarray) -> np.ndarray:
    """TOSCA's +z up -> lit3d's +y up: (x, y, z) -> (x, z, -y)."""
    return np.stack([verts[:, 0], verts[:, 2], -verts[:, 1]], 1)


# --------------------------------------------------------------------- writers (tests, conversions)
def write_off(path, verts, faces) -> None:
    lines = ["OFF", f"{len(verts)} {len(faces)} 0"]
    lines += [" ".join(f"{x:.9g}" for x in v) for v in verts]
    lines += ["3 " + " ".join(str(int(i)) for i in f) for f in faces]
    Path(path).write_text("\n".join(lines) + "\n")


def write_vert_tri(path, verts, faces) -> None:
    path = Path(path)
    np.savetxt(path.with_suffix(".vert"), verts, fmt="%.9g")
    np.savetxt(path.with_suffix(".tri"), np.asarray(faces) + 1, fmt="%d")


def write_mat(path, verts, faces) -> None:
    from scipy.io import savemat

    surface = {"X": verts[:, 0:1], "Y": verts[:, 1:2], "Z": verts[:, 2:3],
               "TRIV": (np.asarray(faces) + 1).astype(np.uint16 if len(verts) < 65535 else np.uint32)}
    savemat(str(path), {"surface": surface})
