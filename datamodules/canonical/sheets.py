"""Look at the bodies before training on them: a labelled contact sheet of shaded meshes, one row
per subject (its canonical pose first, then sampled poses), exactly as they are normalised for
rendering (so a broken limb or a body outside the view shows here first)."""
from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from lit3d.render.depth import ORTHO_MAG
from lit3d.render.shaded import shaded_views
from lit3d.utils.figures import labelled_grid
from lit3d.utils.io import atomic_write_bytes

CELL = 256


def _shaded(verts: np.ndarray, faces: np.ndarray, size: int) -> np.ndarray:
    """``(size, size, 3) uint8`` shaded front view (the depth camera's) of a normalised mesh."""
    import trimesh

    mesh = trimesh.Trimesh(verts, faces, process=False)
    return shaded_views(mesh, [[0.0, 0.0, 1.0]], size=size, extent=ORTHO_MAG)[0]


def pose_sheet(dm, path: str | Path, n_subjects: int = 4, n_poses: int = 5, cell: int = CELL) -> Path:
    """PNG (written atomically) of ``n_subjects`` subjects spread over ``dm``'s source, each in its
    canonical pose and its first ``n_poses`` poses, shaded, ``cell`` px a panel, labelled.
    ``dm`` is a :class:`~datamodules.canonical.CanonicalDataModule` (its meshes and normalisation)."""
    src = dm.source
    subjects = src.subjects()
    picks = [subjects[int(i)] for i in np.unique(np.linspace(0, len(subjects) - 1, min(n_subjects, len(subjects))).astype(int))]
    rows, n_cols = [], 0
    for s in picks:
        poses = list(src.poses(s))[:n_poses]
        cells = [_shaded(*dm.normalized_mesh(s, p), cell) for p in ["canonical", *poses]]
        ids = [str(p) for p in poses]  # pose ids differ per subject (TOSCA): listed per row, 5 a line
        label = s + "\nposes " + ",\n".join(", ".join(ids[i:i + 5]) for i in range(0, len(ids), 5))
        if hasattr(src, "phenotype"):
            label += "\n" + "\n".join(f"{k} {v:.2f}" for k, v in src.phenotype(s).items())
        rows.append({"label": label, "cells": cells})
        n_cols = max(n_cols, len(cells))
    blank = np.full((cell, cell, 3), 255, np.uint8)
    for r in rows:
        r["cells"] += [blank] * (n_cols - len(r["cells"]))
    columns = ["canonical"] + [f"posed {i + 1}" for i in range(n_cols - 1)]
    title = f"{dm.source_kind}: {len(subjects)} subjects, shaded as rendered (normalised, camera on +z)"
    img = labelled_grid(rows, columns, title, cell=cell, left=170)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    buf = io.BytesIO()
    img.save(buf, format="PNG")
    atomic_write_bytes(path, buf.getvalue())
    return path
