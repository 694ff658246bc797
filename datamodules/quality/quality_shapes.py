"""Procedural reference shapes of the synthetic quality set (and the user's own meshes).

:func:`procedural_shape` makes one of :data:`PROCEDURAL_SHAPES` (centred, about unit size, smooth
and rough regions on most); :func:`load_user_meshes` reads every mesh file of a folder. The
distortions applied to them are in :mod:`datamodules.quality.distortions`.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh

from datamodules.cache import stable_int_seed

PROCEDURAL_SHAPES = ("blob", "bumpy", "torus", "rounded_box", "twist", "rock")
MESH_SUFFIXES = (".obj", ".ply", ".off", ".stl")


# --------------------------------------------------------------------------- procedural references
def _sph(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    theta = np.arccos(np.clip(v[:, 2], -1, 1))
    phi = np.arctan2(v[:, 1], v[:, 0])
    return theta, phi


def procedural_shape(name: str, subdivisions: int = 4, seed: int = 0) -> trimesh.Trimesh:
    """One procedural reference shape, centred, about unit size. Smooth and rough regions on most.

    blob: low-frequency radial harmonics; bumpy: smooth body + high-frequency bumps on one
    hemisphere; torus: ridged torus; rounded_box: superellipsoid; twist: twisted bar with
    grooves; rock: multi-octave random radial noise.
    """
    rng = np.random.default_rng(stable_int_seed("shape", name, seed))
    if name == "torus":
        m = trimesh.creation.torus(major_radius=0.7, minor_radius=0.28, major_sections=96, minor_sections=32)
        v = m.vertices.copy()
        ang = np.arctan2(v[:, 1], v[:, 0])
        ring = np.stack([np.cos(ang), np.sin(ang), np.zeros_like(ang)], 1) * 0.7
        off = v - ring
        r = np.linalg.norm(off, axis=1, keepdims=True)
        ridges = 1 + 0.12 * np.clip(np.sin(9 * ang), 0, None)[:, None] * (ang > 0)[:, None]
        return trimesh.Trimesh(ring + off / r * 0.28 * ridges, m.faces, process=False)
    sphere = trimesh.creation.icosphere(subdivisions=subdivisions)
    u = sphere.vertices / np.linalg.norm(sphere.vertices, axis=1, keepdims=True)
    theta, phi = _sph(u)
    if name == "blob":
        r = 1 + 0.18 * np.sin(2 * theta) * np.cos(3 * phi) + 0.1 * np.cos(3 * theta)
        v = u * r[:, None]
    elif name == "bumpy":
        bumps = 0.06 * np.sin(14 * theta) * np.sin(14 * phi) * (u[:, 2] > 0)
        r = 1 + 0.12 * np.cos(2 * theta) + bumps
        v = u * r[:, None]
    elif name == "rounded_box":
        p = 6.0
        s = (np.abs(u) ** p).sum(1) ** (-1 / p)
        v = u * s[:, None] * np.array([1.0, 0.7, 0.5])
        v[:, 2] += 0.04 * np.sin(20 * u[:, 0]) * (u[:, 2] > 0.3)
    elif name == "twist":
        v = u * np.array([0.45, 0.45, 1.2])
        t = v[:, 2] * 1.6
        c, s = np.cos(t), np.sin(t)
        x, y = v[:, 0] * c - v[:, 1] * s, v[:, 0] * s + v[:, 1] * c
        groove = 1 - 0.08 * np.clip(np.sin(6 * np.arctan2(y, x)), 0, None) * (v[:, 2] < 0)
        v = np.stack([x * groove, y * groove, v[:, 2]], 1)
    elif name == "rock":
        r = np.ones(len(u))
        for octave in range(1, 5):
            k = rng.normal(size=(3, 3)) * (1.5 * octave)
            ph = rng.uniform(0, 2 * np.pi, size=3)
            r += (0.12 / octave) * np.sin(u @ k + ph).sum(1) / 3
        v = u * r[:, None]
    else:
        raise KeyError(f"unknown procedural shape '{name}' (known: {', '.join(PROCEDURAL_SHAPES)})")
    return trimesh.Trimesh(v, sphere.faces, process=False)


def merge_by_position(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """``mesh`` with one vertex per position (in place): normals and texture coordinates ignored.

    OBJ files with per-corner normals or UVs load split (the Stanford bunny: 19,794 vertices for
    3,301 positions), and a per-vertex distortion would tear such a surface apart at every seam.
    Faces that merging collapses (two corners on one position) are dropped; no other cleaning.
    """
    mesh.merge_vertices(merge_tex=True, merge_norm=True)
    f = mesh.faces
    keep = (f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 0] != f[:, 2])
    if not keep.all():
        mesh.update_faces(keep)
        mesh.remove_unreferenced_vertices()
    return mesh


def load_user_meshes(folder: str | Path) -> dict[str, trimesh.Trimesh]:
    """Every mesh file in ``folder`` (name = file stem), its vertices merged by position
    (:func:`merge_by_position`); one clear error per unreadable file."""
    folder = Path(folder).expanduser()
    if not folder.is_dir():
        raise FileNotFoundError(f"{folder}: user_mesh_dir not found")
    out = {}
    for p in sorted(folder.iterdir()):
        if p.suffix.lower() not in MESH_SUFFIXES:
            continue
        try:
            m = trimesh.load(p, force="mesh", process=False)
        except Exception as exc:
            raise ValueError(f"{p}: not a readable mesh ({type(exc).__name__}: {exc})") from exc
        if not isinstance(m, trimesh.Trimesh) or len(m.faces) == 0 or len(merge_by_position(m).faces) == 0:
            raise ValueError(f"{p}: empty mesh (no faces)")
        out[p.stem] = m
    if not out:
        raise ValueError(f"{folder}: no mesh files ({', '.join(MESH_SUFFIXES)})")
    return out
