"""Quick pictures of quality pairs for ``lit3d-data show``: orthographic Lambert previews
(NumPy painter's algorithm, no GL) of reference | distorted, one row per pair."""
from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import trimesh

from lit3d.features.matrix import FeatureMatrix


def mesh_pairs_png(fm: FeatureMatrix, sources: Mapping[str, dict], n: int, path: str | Path, tile: int = 128) -> Path:
    """PNG: up to ``n`` pairs of ``fm`` spread over its rows (reference | distorted, meshes from
    ``sources[item]``) with their target."""
    from PIL import Image, ImageDraw

    idx = np.linspace(0, len(fm) - 1, min(int(n), len(fm))).round().astype(int)
    canvas = Image.new("RGB", (tile * 2, (tile + 14) * len(idx)), "white")
    draw = ImageDraw.Draw(canvas)
    for r, i in enumerate(idx):
        src = sources.get(fm.items[i], {})
        for c, key in enumerate(("reference", "distorted")):
            if src.get(key):
                canvas.paste(preview(Path(src[key]), tile), (c * tile, r * (tile + 14) + 14))
        draw.text((2, r * (tile + 14)), f"{fm.items[i]}  {fm.target_name} {fm.target[i]:.2f}", fill="black")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    canvas.save(path)
    return path


def preview(mesh_path: Path, size: int):
    """A quick orthographic Lambert preview of a mesh (numpy painter's algorithm, no GL)."""
    from PIL import Image

    m = trimesh.load(mesh_path, force="mesh", process=False)
    v = m.vertices - m.bounds.mean(0)
    v = v / max(np.abs(v).max(), 1e-9) * 0.45 * size
    c, s = math.cos(0.6), math.sin(0.6)
    rot = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]) @ np.array([[1, 0, 0], [0, math.cos(0.4), -math.sin(0.4)],
                                                                  [0, math.sin(0.4), math.cos(0.4)]])
    v = v @ rot.T
    tri = v[m.faces]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
    shade = np.clip(n @ np.array([0.3, 0.4, 0.87]), 0, 1)
    order = np.argsort(tri[:, :, 2].mean(1))
    from PIL import ImageDraw

    img = Image.new("L", (size, size), 255)
    d = ImageDraw.Draw(img)
    for f in order:
        if n[f, 2] <= 0:
            continue
        pts = [(float(x + size / 2), float(size / 2 - y)) for x, y, _ in tri[f]]
        d.polygon(pts, fill=int(40 + 200 * shade[f]))
    return img.convert("RGB")
