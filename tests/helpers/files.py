"""Writers of real input files for tests: a depth PNG, a folder tree's bytes (to check nothing changed),
and a MOS dataset in LIRIS/EPFL's published layout."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import openpyxl
import trimesh
from PIL import Image


def write_box_mesh(path):
    path.parent.mkdir(parents=True, exist_ok=True)
    trimesh.creation.box().export(path)


def write_xlsx(path, rows, title_rows=(("LIRIS/EPFL subjective scores",),), sheet="MOS"):
    wb = openpyxl.Workbook()
    ws = wb.active
    ws.title = sheet
    for r in title_rows:
        ws.append(list(r))
    for r in rows:
        ws.append(list(r))
    wb.save(path)


def write_depth_png(path: Path) -> Path:
    d = np.zeros((24, 32), np.uint16)
    d[6:18, 8:24] = 1500
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(d).save(path)
    return path


def file_tree(root: Path) -> dict[str, bytes | None]:
    """Every path under ``root`` -> its bytes (None for folders): what a run must leave as it was."""
    return {str(p.relative_to(root)): (p.read_bytes() if p.is_file() else None) for p in sorted(root.rglob("*"))}


def liris_epfl(root, rows=None, missing=()):
    shapes = ("Armadillo", "Dyno", "RockerArm", "Venus")
    for s in shapes:
        write_box_mesh(root / s / f"{s}.obj")
        for k in (1, 2):
            if f"{s}_noise_{k}" not in missing:
                write_box_mesh(root / s / f"{s}_noise_{k}.obj")
    if rows is None:
        rows = [("Model", "Observer 1", "MOS")] + [(f"{s}_noise_{k}", 1, 2.5 * k) for s in shapes for k in (1, 2)]
    write_xlsx(root / "MOS_GeneralPurpose.xlsx", rows)
    return root
