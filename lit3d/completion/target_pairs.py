"""The input reader of ``lit3d-eval-folder PRED_DIR --targets TARGET_DIR``: pair a folder of predicted
shapes with a folder of target shapes by file stem, and read each file.

Files: the top-level files of each folder whose suffix (any case) is one of

- ``.obj .ply .off``: a triangle mesh, read by :func:`lit3d.render.convert.to_mesh` (trimesh;
  vertices as stored: no centring, scaling or alignment; a ``.ply`` of points only is meshed there);
- ``.npz .npy``: an occupancy grid ``(D, H, W)`` (also ``(1, D, H, W)`` or ``(D, H, W, 1)``) of
  bool/{0, 1} or probabilities in [0, 1], or an SDF under the npz key ``sdf`` (occupied where
  negative), read by :func:`lit3d.completion.folder_eval.read_grid_prediction`; a prediction is
  occupied where ``>= threshold``, a target where ``>= 0.5``.

Other files (and subfolders) are left alone. Pairing: ``PRED_DIR/<stem>.<ext>`` with
``TARGET_DIR/<stem>.<ext2>`` (any of the suffixes each: ``chair_01.obj`` with ``chair_01.ply``).
Two files of one stem in one folder are ambiguous; every target needs a prediction; predictions
without a target are returned apart (reported, not scored). Every problem raises
:class:`~lit3d.render.convert.ShapeError`: one line naming the file (missing, unreadable, empty,
no faces, NaN vertices, a grid without an occupied voxel).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from lit3d.completion.folder_eval import GRID_SUFFIXES, MESH_SUFFIXES, read_grid_prediction
from lit3d.render.convert import ShapeError, to_mesh

SHAPE_SUFFIXES = MESH_SUFFIXES + GRID_SUFFIXES
TARGET_OCCUPIED = 0.5  # a target grid is occupied where >= this


@dataclass(frozen=True)
class ShapePair:
    """One prediction file and its target file, paired by ``stem``."""

    stem: str
    prediction: Path
    target: Path


@dataclass
class Shape:
    """One shape file as read: ``mesh`` (a ``trimesh.Trimesh``, vertices as stored) or ``grid``
    (``(D, H, W)`` bool occupancy); the other is None."""

    path: Path
    mesh: Any = None
    grid: np.ndarray | None = None

    @property
    def kind(self) -> str:
        return "mesh" if self.mesh is not None else "grid"


def _suffix_list() -> str:
    return ",".join(s[1:] for s in SHAPE_SUFFIXES)


def shape_files(folder: Path, role: str) -> dict[str, Path]:
    """``stem -> file`` of the shape files directly in ``folder`` (sorted by stem). ``role`` names the
    folder in the errors (``"predictions"``, ``"targets"``): missing, not a folder, no shape file, two
    files of one stem."""
    folder = Path(folder)
    if not folder.is_dir():
        raise ShapeError(f"{folder}: {role} folder not found" if not folder.exists()
                         else f"{folder}: is a file, expected a folder of {role}")
    found: dict[str, Path] = {}
    for path in sorted(folder.iterdir()):
        if path.suffix.lower() not in SHAPE_SUFFIXES or path.is_dir():
            continue
        if path.stem in found:
            raise ShapeError(f"{found[path.stem]}: ambiguous {role[:-1]}, also {path.name}")
        found[path.stem] = path
    if not found:
        raise ShapeError(f"{folder}: no {role} here (files named <stem>.{{{_suffix_list()}}})")
    return dict(sorted(found.items()))


def pair_folders(pred_dir: Path, target_dir: Path) -> tuple[list[ShapePair], list[Path]]:
    """``(pairs, unpaired predictions)``: every target of ``target_dir`` with the prediction of its
    stem, in stem order. A target without a prediction raises :class:`ShapeError` naming the file
    looked for (and how many other targets lack one)."""
    preds, targets = shape_files(pred_dir, "predictions"), shape_files(target_dir, "targets")
    missing = [stem for stem in targets if stem not in preds]
    if missing:
        more = f" (and {len(missing) - 1} more targets without one)" if len(missing) > 1 else ""
        raise ShapeError(f"{Path(pred_dir) / missing[0]}.{{{_suffix_list()}}}: missing prediction of the target "
                         f"{targets[missing[0]]}{more}")
    pairs = [ShapePair(stem, preds[stem], path) for stem, path in targets.items()]
    return pairs, [path for stem, path in preds.items() if stem not in targets]


def read_shape(path: Path, threshold: float = TARGET_OCCUPIED) -> Shape:
    """The mesh or the occupancy grid (occupied where ``>= threshold``) of one shape file (module doc)."""
    path = Path(path)
    if path.suffix.lower() in MESH_SUFFIXES:
        return Shape(path, mesh=to_mesh(path))
    grid = read_grid_prediction(path, None) >= threshold
    if not grid.any():
        raise ShapeError(f"{path}: no occupied voxel (at >= {threshold:g}): no surface to score")
    return Shape(path, grid=grid)


__all__ = ["SHAPE_SUFFIXES", "TARGET_OCCUPIED", "Shape", "ShapePair", "pair_folders", "read_shape", "shape_files"]
