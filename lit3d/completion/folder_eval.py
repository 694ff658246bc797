"""Score another method's completions (a folder of voxel grids or meshes) against the targets of a
prepared completion data split, with the test metrics of :class:`lit3d.completion.module.CompletionTask`:
IoU and cross-entropy (grids only) and the surface metrics (:mod:`lit3d.metrics.surface`).

Layout: the prediction of the cached item ``items/<split>/<stem>.npz`` is
``PRED_DIR/<split>/<stem>.<ext>`` or ``PRED_DIR/<stem>.<ext>`` (``<split>`` as in the cache:
``test_same``, ``test_cross``, ``test_unseen``, ``test_unseen_cross``), ``<ext>`` one of
``.npz .npy`` (an occupancy grid of the target's shape ``(R, R, R)``, also ``(1, R, R, R)`` or
``(R, R, R, 1)``: bool/int {0, 1} or probabilities in [0, 1], occupied where ``>= threshold``; or an
SDF under the npz key ``sdf``, occupied where negative) or ``.obj .ply .off`` (a triangle mesh in
the target grid's frame: ``unit`` = the grid is the cube ``[-0.5, 0.5]^3``; ``voxel`` = vertex
``(x, y, z)`` at grid index ``[x, y, z]``). Any problem raises :class:`ShapeError` naming the file.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from datamodules.cache import DataError, read_manifest
from datamodules.completion.voxel_cache import TEST_SPLITS, load_pair
from lit3d.completion.split_metrics import split_values
from lit3d.completion.surface_eval import surface_values
from lit3d.metrics.surface import SurfaceMetrics, SurfaceSample, sample_mesh
from lit3d.metrics.voxel import VoxelSweepMetrics, default_thresholds
from lit3d.render.convert import ShapeError, is_sdf, load_array, to_mesh
from lit3d.utils.shapenet_categories import SEEN_CATEGORIES, UNSEEN_CATEGORIES

GRID_SUFFIXES = (".npz", ".npy")
MESH_SUFFIXES = (".obj", ".ply", ".off")
MESH_FRAMES = ("unit", "voxel")


@dataclass(frozen=True)
class FolderScoring:
    """What :func:`score_folder` needs besides the folders: ``threshold`` for probability grids,
    ``mesh_frame`` (``unit`` | ``voxel``) and the surface sizes of ``evaluation.surface``."""

    points: int
    fscore_at: tuple[float, ...]
    seed: int = 0
    threshold: float = 0.5
    mesh_frame: str = "unit"


def test_items(data_dir: Path) -> dict[str, list[dict]]:
    """The manifest's test items per split (in manifest order); :class:`DataError` without a manifest."""
    manifest = read_manifest(data_dir)
    if manifest is None:
        raise DataError(f"{data_dir}: no prepared completion data (no manifest.json; run lit3d-data first)")
    out: dict[str, list[dict]] = {}
    for it in manifest.get("items", []):
        if it.get("split") in TEST_SPLITS:
            out.setdefault(it["split"], []).append(it)
    if not out:
        raise DataError(f"{data_dir}: the manifest lists no test items ({', '.join(TEST_SPLITS)})")
    return out


def prediction_candidates(pred_dir: Path, split: str, item: dict) -> list[Path]:
    """Where the prediction of ``item`` may be, in the order looked at."""
    stem = Path(item["file"]).stem
    return [base / f"{stem}{ext}" for base in (pred_dir / split, pred_dir) for ext in GRID_SUFFIXES + MESH_SUFFIXES]


def find_prediction(pred_dir: Path, split: str, item: dict) -> Path | None:
    """The one prediction file of ``item``; None when there is none; two in one folder are an error."""
    for folder in (pred_dir / split, pred_dir):
        found = [p for p in prediction_candidates(pred_dir, split, item) if p.parent == folder and p.is_file()]
        if len(found) > 1:
            raise ShapeError(f"{found[0]}: ambiguous prediction, also {', '.join(p.name for p in found[1:])}")
        if found:
            return found[0]
    return None


def read_grid_prediction(path: Path, shape: tuple[int, ...] | None) -> np.ndarray:
    """``(R, R, R)`` float32 occupancy probabilities in [0, 1] of a grid prediction file (module doc;
    an SDF gives 1 where negative, else 0), checked against the target's ``shape`` (None: any 3-D grid)."""
    arr = load_array(path)
    sdf = is_sdf(arr)
    arr = np.asarray(arr)
    if arr.dtype.kind not in "biuf":
        raise ShapeError(f"{path}: array has dtype {arr.dtype}, expected bool, integer or float values")
    if arr.ndim == 4 and 1 in (arr.shape[0], arr.shape[-1]):
        arr = arr.reshape(arr.shape[1:] if arr.shape[0] == 1 else arr.shape[:-1])
    if arr.size == 0:
        raise ShapeError(f"{path}: empty array")
    if shape is None and arr.ndim != 3:
        raise ShapeError(f"{path}: array of shape {tuple(arr.shape)}, expected a 3-D grid")
    if shape is not None and tuple(arr.shape) != tuple(shape):
        raise ShapeError(f"{path}: grid of shape {tuple(arr.shape)}, expected the target's {tuple(shape)}")
    values = arr.astype(np.float64, copy=False)
    if not np.isfinite(values).all():
        raise ShapeError(f"{path}: grid contains NaN or inf")
    if sdf:
        return (values < 0).astype(np.float32)
    if values.min() < 0 or values.max() > 1:
        raise ShapeError(f"{path}: values in [{values.min():.3g}, {values.max():.3g}], expected occupancy in "
                         "[0, 1] (an SDF goes under the npz key 'sdf')")
    return values.astype(np.float32)


def mesh_prediction(path: Path, side: int, frame: str, points: int, seed: int) -> SurfaceSample | None:
    """Surface samples of a mesh prediction, moved into the unit frame of :mod:`lit3d.metrics.surface`."""
    mesh = to_mesh(path)
    if frame == "voxel":
        mesh = mesh.copy()
        mesh.vertices = (np.asarray(mesh.vertices, dtype=np.float64) + 0.5) / side - 0.5
    return sample_mesh(mesh, points, seed)


def score_folder(pred_dir: Path, data_dir: Path, cfg: FolderScoring, splits: Sequence[str] | None = None,
                 ) -> tuple[dict[str, float], dict]:
    """Score every prediction of ``pred_dir`` against the targets of the prepared ``data_dir``.

    Args:
        splits: cache split names to score; None = every test split with at least one prediction.
    Returns:
        ``(metrics, info)``: the ``test/<split>/...`` keys of the model row of results.md (IoU, pooled
        IoU and cross-entropy only for splits predicted as grids), and ``info`` (counts, kinds, files).
    Raises:
        ShapeError / DataError naming the file: a missing or bad prediction, a bad cache item.
    """
    if cfg.mesh_frame not in MESH_FRAMES:
        raise ValueError(f"--mesh-frame {cfg.mesh_frame}: expected one of {', '.join(MESH_FRAMES)}")
    if not 0 < cfg.threshold <= 1:
        raise ValueError(f"--threshold {cfg.threshold}: expected a value in (0, 1]")
    if not pred_dir.is_dir():
        raise ShapeError(f"{pred_dir}: predictions folder not found" if not pred_dir.exists()
                         else f"{pred_dir}: is a file, expected a folder of predictions")
    items = test_items(data_dir)
    if splits is None:
        splits = [s for s in TEST_SPLITS if any(find_prediction(pred_dir, s, it) for it in items.get(s, []))]
        if not splits:
            first = next(iter(items.values()))[0]
            raise ShapeError(f"{pred_dir}: no prediction named like the targets of {data_dir} (e.g. "
                             f"{prediction_candidates(pred_dir, first['split'], first)[0]})")
    for s in splits:
        if s not in items:
            raise ValueError(f"--split {s}: not a test split of {data_dir} (it has {', '.join(items)})")
    # the module's evaluation categories (then per-category keys as lit3d-eval's), and any other of the data
    known = list(SEEN_CATEGORIES) + list(UNSEEN_CATEGORIES)
    categories = list(dict.fromkeys(known + [it["category"] for s in splits for it in items[s]]))
    names = [s.removeprefix("test_") for s in splits]
    grid = torch.unique(torch.cat([default_thresholds(), torch.tensor([cfg.threshold], dtype=torch.float64)]))
    iou = {f"{n}_model": VoxelSweepMetrics(categories, grid) for n in names}
    surface = {f"{n}_model": SurfaceMetrics(categories, cfg.points, cfg.fscore_at, cfg.seed) for n in names}
    info: dict = {"splits": {}}
    grid_splits = []
    for split, name in zip(splits, names):
        kinds = {"grid": 0, "mesh": 0}
        for it in items[split]:
            path = find_prediction(pred_dir, split, it)
            if path is None:
                exts = ",".join(e[1:] for e in GRID_SUFFIXES + MESH_SUFFIXES)
                raise ShapeError(f"{pred_dir}/[{split}/]{Path(it['file']).stem}.{{{exts}}}: missing prediction "
                                 f"of the {split} target {it['file']}")
            target = torch.from_numpy(load_pair(data_dir / it["file"])[1].astype(np.float32))[None, None]
            cat = torch.tensor([categories.index(it["category"])])
            if path.suffix.lower() in GRID_SUFFIXES:
                probs = torch.from_numpy(read_grid_prediction(path, tuple(target.shape[-3:])))[None, None]
                iou[f"{name}_model"].update(probs, target, cat)
                surface[f"{name}_model"].update(probs >= cfg.threshold, target, cat)
                kinds["grid"] += 1
            else:
                sample = mesh_prediction(path, int(target.shape[-1]), cfg.mesh_frame, cfg.points, cfg.seed)
                surface[f"{name}_model"].update([sample], target, cat)
                kinds["mesh"] += 1
        info["splits"][split] = {"items": len(items[split]), **kinds}
        if kinds["mesh"] == 0:
            grid_splits.append(name)
    metrics = split_values({k: v for k, v in iou.items() if k[:-len("_model")] in grid_splits}, grid_splits,
                           ("model",), {"model": cfg.threshold}, grid.float(), categories)
    metrics.update(surface_values(surface, names, ("model",), categories))
    return metrics, info
