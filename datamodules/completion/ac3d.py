"""AC3D models (``.ac``, and TORCS's ``.acc`` variant) read into triangle meshes.

trimesh reads neither format, so this is a reader of its own, written from the AC3D file format
description (AC3D's ``ac3dfileformat.txt``) and checked on the files of the Debian packages
``flightgear-data-ai``, ``crrcsim-data`` and ``torcs-data``. A file is::

    AC3Db                                   header (AC3D + a version letter)
    MATERIAL "name" rgb ... trans 0         any number of material lines (ignored here)
    OBJECT world                            a tree of objects; each one is
    name "fuselage"                         optional: name, data N (N characters follow),
    loc x y z                               texture, texrep, texoff, rot (9 floats), loc (3),
    rot r00 r01 r02 r10 ... r22             crease, url, hidden, locked, folded, subdiv
    numvert n                               n lines "x y z" (.acc: "x y z nx ny nz")
    numsurf m                               m surfaces: "SURF flags", "mat i", "refs k" and k
    SURF 0x10                               lines "vertex u v" (.acc: more u v pairs)
    mat 0
    refs 3
    0 0 0 ...
    kids c                                  c child OBJECTs follow (recursively)

A surface's type is the low nibble of its flags: 0 polygon (fan-triangulated), 1 closed line
and 2 line (dropped: no area), 4 triangle strip (TORCS ``.acc``; alternate triangles flipped
so the strip keeps one winding). An object's vertices are placed in its parent's frame by
``v @ rot + loc`` (row vectors, as plib and OpenSceneGraph read them), down the tree. A file
that ends cleanly after an object although its parent announced more ``kids`` is accepted (some
exporters, Blender's among them, overstate the world's kids), as plib does; a file cut inside an
object is an error.

:func:`read_ac_objects` gives one :class:`AcObject` per object with triangles (world frame), so a
catalogue can leave parts out (LOD copies, shadows); :func:`read_ac` gives one
``trimesh.Trimesh``. A bad file raises :class:`~datamodules.cache.DataError` naming the file,
the line and the problem (truncated, bad number, vertex index out of range, unknown surface type).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from datamodules.cache import DataError
from datamodules.completion.archives import source_bytes

SURF_POLYGON, SURF_CLOSED_LINE, SURF_LINE, SURF_STRIP = 0, 1, 2, 4
_SKIPPED_KEYS = {"texture", "texrep", "texoff", "crease", "url", "hidden", "locked", "folded", "subdiv", "shader"}


@dataclass
class AcObject:
    """One AC3D object with triangles: ``name`` (``""`` when unnamed), ``path`` (names from the
    root, ``/``-joined), ``vertices`` (V, 3) float64 in the file's world frame, ``faces`` (F, 3)
    int64 into ``vertices``, ``depth`` (0 for the world object)."""

    name: str
    path: str
    vertices: np.ndarray
    faces: np.ndarray
    depth: int


class _Lines:
    """The file's lines with a cursor; every error names the file and the line number."""

    def __init__(self, text: str, where: str):
        self.lines = text.splitlines()
        self.i = 0
        self.where = where

    def fail(self, problem: str, line: int | None = None) -> DataError:
        n = self.i if line is None else line
        return DataError(f"{self.where}: line {n}: {problem}")

    def next(self, what: str) -> str:
        while self.i < len(self.lines):
            line = self.lines[self.i].strip()
            self.i += 1
            if line:
                return line
        raise DataError(f"{self.where}: truncated: end of file while reading {what}")

    def at_end(self) -> bool:
        """True when only blank lines are left."""
        return all(not line.strip() for line in self.lines[self.i:])

    def skip_chars(self, n: int) -> None:
        """Skip the ``n`` characters of a ``data n`` block (they may span lines)."""
        left = n
        while left > 0:
            if self.i >= len(self.lines):
                raise DataError(f"{self.where}: truncated: end of file inside a 'data {n}' block")
            left -= len(self.lines[self.i]) + 1
            self.i += 1


def _floats(lines: _Lines, words: list[str], count: int, what: str) -> list[float]:
    try:
        vals = [float(w) for w in words[:count]]
    except ValueError:
        raise lines.fail(f"bad number in {what}: {' '.join(words)!r}") from None
    if len(vals) < count:
        raise lines.fail(f"{what}: expected {count} numbers, got {len(vals)}")
    return vals


def _int(lines: _Lines, words: list[str], what: str) -> int:
    try:
        n = int(words[1], 0)
    except (IndexError, ValueError):
        raise lines.fail(f"bad {what} line {' '.join(words)!r}") from None
    if n < 0:
        raise lines.fail(f"negative count in {' '.join(words)!r}")
    return n


def _surface_triangles(lines: _Lines, numvert: int) -> list[tuple[int, int, int]]:
    """Read one SURF block (the SURF line already consumed is in ``lines``) -> its triangles."""
    words = lines.lines[lines.i - 1].split()
    try:
        flags = int(words[1], 16) if words[1].lower().startswith("0x") else int(words[1], 0)
    except (IndexError, ValueError):
        raise lines.fail(f"bad SURF line {' '.join(words)!r}") from None
    kind = flags & 0xF
    refs: list[int] = []
    while True:
        line = lines.next("a surface")
        key, *rest = line.split()
        if key == "mat":
            continue
        if key != "refs":
            raise lines.fail(f"expected 'mat' or 'refs' in a surface, got {line!r}")
        n = _int(lines, [key, *rest], "refs")
        for _ in range(n):
            w = lines.next("surface refs").split()
            try:
                idx = int(w[0])
            except ValueError:
                raise lines.fail(f"bad vertex reference {' '.join(w)!r}") from None
            if not 0 <= idx < numvert:
                raise lines.fail(f"vertex index {idx} out of range (numvert {numvert})")
            refs.append(idx)
        break
    if kind in (SURF_CLOSED_LINE, SURF_LINE):
        return []
    if kind == SURF_POLYGON:
        return [(refs[0], refs[k], refs[k + 1]) for k in range(1, len(refs) - 1)]
    if kind == SURF_STRIP:
        return [(refs[k], refs[k + 1], refs[k + 2]) if k % 2 == 0 else (refs[k + 1], refs[k], refs[k + 2])
                for k in range(len(refs) - 2)]
    raise lines.fail(f"unknown surface type {kind} (flags {words[1]}): expected 0 polygon, 1/2 line or 4 strip")


def _read_object(lines: _Lines, parent: np.ndarray, parent_path: str, depth: int, out: list[AcObject]) -> None:
    """Read the OBJECT whose header line was just consumed, then its kids (recursively)."""
    if depth > 64:
        raise lines.fail("objects nested more than 64 deep")
    rot, loc = np.eye(3), np.zeros(3)
    name, verts, tris = "", np.zeros((0, 3)), []
    while True:
        line = lines.next("an object")
        words = line.split()
        key = words[0]
        if key == "name":
            name = line[4:].strip().strip('"')
        elif key == "data":
            lines.skip_chars(_int(lines, words, "data"))
        elif key == "rot":
            rot = np.asarray(_floats(lines, words[1:], 9, "rot"), np.float64).reshape(3, 3)
        elif key == "loc":
            loc = np.asarray(_floats(lines, words[1:], 3, "loc"), np.float64)
        elif key == "numvert":
            n = _int(lines, words, "numvert")
            verts = np.asarray([_floats(lines, lines.next("vertices").split(), 3, "a vertex") for _ in range(n)],
                               np.float64).reshape(n, 3)
        elif key == "numsurf":
            for _ in range(_int(lines, words, "numsurf")):
                line = lines.next("surfaces")
                if not line.startswith("SURF"):
                    raise lines.fail(f"expected SURF, got {line!r}")
                tris += _surface_triangles(lines, len(verts))
        elif key == "kids":
            kids = _int(lines, words, "kids")
            break
        elif key in _SKIPPED_KEYS:
            continue
        else:
            raise lines.fail(f"unknown line in an object: {line[:60]!r}")
    local = np.eye(4)
    local[:3, :3], local[3, :3] = rot, loc
    world = local @ parent  # row vectors: v_world = [v, 1] @ local @ parent
    path = f"{parent_path}/{name}" if parent_path else name
    if tris:
        v = np.c_[verts, np.ones(len(verts))] @ world
        out.append(AcObject(name, path, v[:, :3], np.asarray(tris, np.int64), depth))
    for _ in range(kids):
        if lines.at_end():  # exporters (Blender's among them) overstate a group's kids: the file ends cleanly
            return
        line = lines.next(f"the kids of object {name or '(unnamed)'}")
        if not line.startswith("OBJECT"):
            raise lines.fail(f"expected OBJECT, got {line[:60]!r}")
        _read_object(lines, world, path, depth + 1, out)


def _text(source: str | Path | bytes, where: str | None) -> tuple[str, str]:
    """(text, name for messages) of a path, an ``archive::member`` or bytes."""
    data, where = source_bytes(source, where)
    return data.decode("latin-1"), where


def read_ac_objects(source: str | Path | bytes, where: str | None = None) -> list[AcObject]:
    """The objects with triangles of an AC3D file (path, ``archive::member`` or bytes), world frame.

    Raises:
        DataError: naming ``where`` (default: the path) and the problem.
    """
    text, where = _text(source, where)
    lines = _Lines(text, where)
    head = lines.next("the header")
    if not head.startswith("AC3D"):
        raise DataError(f"{where}: not an AC3D file (first line {head[:20]!r}, expected 'AC3Db')")
    out: list[AcObject] = []
    while lines.i < len(lines.lines):
        line = lines.lines[lines.i].strip()
        lines.i += 1
        if not line or line.startswith("MATERIAL"):
            continue
        if not line.startswith("OBJECT"):
            raise lines.fail(f"expected MATERIAL or OBJECT at top level, got {line[:60]!r}")
        _read_object(lines, np.eye(4), "", 0, out)
    return out


def read_ac(source: str | Path | bytes, where: str | None = None):
    """An AC3D file as one ``trimesh.Trimesh`` (every object's triangles, world frame, the file's axes).

    Raises:
        DataError: unreadable, truncated or garbled, or no triangle at all.
    """
    import trimesh

    objects = read_ac_objects(source, where)
    if not objects:
        raise DataError(f"{where or source}: AC3D file without triangles")
    return trimesh.Trimesh(*merge_objects(objects), process=False)


def merge_objects(objects: list[AcObject]) -> tuple[np.ndarray, np.ndarray]:
    """(V, 3) float64 vertices and (F, 3) int64 faces of ``objects`` concatenated."""
    verts, faces, base = [], [], 0
    for o in objects:
        verts.append(o.vertices)
        faces.append(o.faces + base)
        base += len(o.vertices)
    return np.concatenate(verts), np.concatenate(faces)
