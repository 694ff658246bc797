"""Reader for the 3D-RecGAN++ ShapeNet depth-voxel release.

Layouts accepted (``root`` holds one folder per category)::

    P1_<synset>_<category>/{train_125,test_125,test_216}_{25d,3d}_vox256/<id>_<a>_<b>_<c>.npz   (current)
    P1_<synset>_<category>/{train,test}_{25d,3d}_vox256/<id>_<a>_<b>_<c>.npz                      (older; no
                                                                                                    view set = 125)

The older release spells couch ``coach``. Each ``.npz`` holds ``arr_0``: int8
``(Dx, Dy, Dz, 1)`` in {0,1}, the longest side about ``raw_res`` = 256 (sometimes
257/258). The ``_25d_`` (partial input) and ``_3d_`` (target) files of one view have
the same name and shape: they are paired by name, never by listing order.

Preparation of one pair: centre-pad/crop both grids to ``raw_res^3``; the target is
max-pooled to ``target_res`` (no-op at 256); the input is the padded partial grid
max-pooled to ``target_res / input_factor`` (64^3 at paper scale).

Splits: ``val_125`` / ``val_216`` folders, when a category has them, -> ``val``; otherwise
whole shape ids of ``train_*`` are held out as ``val`` with every view of them in every
train view set (about ``val_fraction`` of the ids, chosen by a seeded hash of the id; when a
category has a single train id, some of its views are held out instead); ``train_*`` ->
``train``, ``test_125`` -> ``test_same``, ``test_216`` -> ``test_cross``; categories in
``unseen_categories`` -> ``test_unseen`` (125 views, thesis table 3.6) and
``test_unseen_cross`` (216 views, table 3.5). Category folder names go through
:data:`lit3d.utils.shapenet_categories.CATEGORY_ALIASES` (``coach``/``sofa`` -> couch,
``airplane`` -> plane, ``gun``/``rifle`` -> firearm, ...).
"""
from __future__ import annotations

import logging
import os
import re
import zipfile
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from datamodules.cache import DataError, stable_hash
from datamodules.completion.voxel_cache import max_pool_bool
from lit3d.utils.shapenet_categories import CATEGORY_ALIASES

log = logging.getLogger("lit3d.data")

DIR_RE = re.compile(r"^(?P<split>train|val|test)(?:_(?P<views>125|216))?_(?P<kind>25d|3d)_vox(?P<res>\d+)$")
FILE_RE = re.compile(r"^(?P<id>.+)_(?P<a>\d+)_(?P<b>\d+)_(?P<c>\d+)\.npz$")
VIEW_SETS = {"125": "same", "216": "cross"}

RECGAN_RAW_RES = 256  # the release's grids: the longest side about 256 voxels


@dataclass(frozen=True)
class RecganPair:
    """One view of one shape: paths of its partial (25d) and complete (3d) grids."""

    category: str
    synset: str
    folder: str        # e.g. "train_125" (older layout: "train")
    split_kind: str    # "train" | "val" | "test"
    view_set: str      # "same" (125) | "cross" (216)
    shape_id: str
    view: str          # "a_b_c"
    input_path: Path
    target_path: Path

    @property
    def name(self) -> str:
        return f"{self.category}_{self.shape_id}_{self.view}"


def parse_category_folder(name: str) -> tuple[str, str]:
    """``P1_03001627_chair`` -> ("03001627", "chair"); ``coach`` is read as couch."""
    parts = name.split("_")
    category = parts[-1].lower()
    synset = parts[-2] if len(parts) >= 2 else ""
    return synset, CATEGORY_ALIASES.get(category, category)


def index_recgan(root: str | os.PathLike, skip_bad: bool = False) -> tuple[list[RecganPair], list[str]]:
    """All input/target pairs under ``root``, sorted by (category, folder, name); plus the problems skipped.

    Raises:
        DataError: ``root`` missing or without category folders; with ``skip_bad=False``
            also an unpaired file or a badly named file (the message names it).
    """
    root = Path(root)
    if not root.is_dir():
        raise DataError(f"{root}: 3D-RecGAN++ data folder not found (set data.root=PATH)")
    problems: list[str] = []

    def bad(msg: str) -> None:
        if not skip_bad:
            raise DataError(msg)
        log.warning("skipping: %s", msg)
        problems.append(msg)

    pairs: list[RecganPair] = []
    cat_dirs = sorted(p for p in root.iterdir() if p.is_dir() and any(DIR_RE.match(q.name) for q in p.iterdir()))
    if not cat_dirs:
        raise DataError(f"{root}: no category folders like P1_<synset>_<category>/train_125_25d_vox256 found")
    for cdir in cat_dirs:
        synset, category = parse_category_folder(cdir.name)
        groups: dict[tuple[str, str | None], dict[str, Path]] = defaultdict(dict)
        for sub in sorted(cdir.iterdir()):
            m = DIR_RE.match(sub.name)
            if not m or not sub.is_dir():
                continue
            groups[(m["split"], m["views"])][m["kind"]] = sub
        for (split_kind, views), dirs in sorted(groups.items(), key=lambda kv: (kv[0][0], kv[0][1] or "")):
            folder = split_kind if views is None else f"{split_kind}_{views}"
            view_set = VIEW_SETS.get(views or "125")
            if "25d" not in dirs or "3d" not in dirs:
                have = next(iter(dirs.values()))
                bad(f"{have}: no matching {'_3d_' if '25d' in dirs else '_25d_'} folder for this split")
                continue
            inputs = {p.name: p for p in dirs["25d"].iterdir() if p.suffix == ".npz"}
            targets = {p.name: p for p in dirs["3d"].iterdir() if p.suffix == ".npz"}
            for name in sorted(set(inputs) ^ set(targets)):
                path = inputs.get(name) or targets.get(name)
                other = "_3d_ (target)" if name in inputs else "_25d_ (input)"
                bad(f"{path}: unpaired file, no {other} file of the same name")
            for name in sorted(set(inputs) & set(targets)):
                m = FILE_RE.match(name)
                if not m:
                    bad(f"{inputs[name]}: file name is not <shape_id>_<a>_<b>_<c>.npz")
                    continue
                pairs.append(RecganPair(
                    category=category, synset=synset, folder=folder, split_kind=split_kind, view_set=view_set,
                    shape_id=m["id"], view=f"{m['a']}_{m['b']}_{m['c']}",
                    input_path=inputs[name], target_path=targets[name]))
    return pairs, problems


def load_grid(path: str | os.PathLike) -> np.ndarray:
    """One release ``.npz`` -> (Dx, Dy, Dz) bool.

    Raises:
        DataError: naming the file: unreadable, no ``arr_0``, wrong ndim, size 0,
            wrong dtype or values (see :func:`occupancy_problem`). An all-empty grid is
            returned (:func:`convert_pair` rejects it after comparing the pair's shapes).
    """
    try:
        with np.load(path, allow_pickle=False) as z:
            if "arr_0" not in z.files:
                raise DataError(f"{path}: missing key 'arr_0' (keys: {z.files})")
            arr = z["arr_0"]
    except DataError:
        raise
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise DataError(f"{path}: unreadable .npz ({type(exc).__name__}: {exc})") from exc
    if arr.ndim == 4 and arr.shape[-1] == 1:
        arr = arr[..., 0]
    if arr.ndim != 3:
        raise DataError(f"{path}: arr_0 has shape {arr.shape}, expected (Dx, Dy, Dz, 1) or (Dx, Dy, Dz)")
    if arr.size == 0:
        raise DataError(f"{path}: arr_0 is empty {arr.shape}")
    problem = occupancy_problem(arr)
    if problem:
        raise DataError(f"{path}: arr_0 {problem}")
    return arr > 0


def occupancy_problem(arr: np.ndarray) -> str | None:
    """Why ``arr`` is not an occupancy grid (bool, or int/float holding only 0 and 1), or None."""
    if arr.dtype.kind not in "biuf":
        return f"has dtype {arr.dtype}, expected int8 occupancy in {{0, 1}}"
    if arr.dtype.kind != "b":
        if arr.dtype.kind == "f" and not np.isfinite(arr).all():
            return f"has dtype {arr.dtype} with NaN or inf, expected int8 occupancy in {{0, 1}}"
        lo, hi = arr.min(), arr.max()
        if lo < 0 or hi > 1 or (arr.dtype.kind == "f" and not np.isin(arr, (0, 1)).all()):
            return f"has dtype {arr.dtype} with values in [{lo:g}, {hi:g}], expected int8 occupancy in {{0, 1}}"
    return None


def centre_fit(grid: np.ndarray, size: int) -> np.ndarray:
    """Centre-pad (zeros) or centre-crop every axis of a 3D grid to ``size``."""
    out = np.zeros((size, size, size), dtype=grid.dtype)
    src, dst = [], []
    for n in grid.shape:
        if n >= size:
            s = (n - size) // 2
            src.append(slice(s, s + size))
            dst.append(slice(0, size))
        else:
            s = (size - n) // 2
            src.append(slice(0, n))
            dst.append(slice(s, s + n))
    out[tuple(dst)] = grid[tuple(src)]
    return out


def max_pool(grid: np.ndarray, out_res: int) -> np.ndarray:
    """(R, R, R) bool -> (out_res,)*3 bool by max-pooling R / out_res blocks."""
    r = grid.shape[0]
    if r % out_res:
        raise ValueError(f"grid size {r} is not a multiple of {out_res}")
    return max_pool_bool(grid, r // out_res)


def convert_pair(pair: RecganPair, raw_res: int = RECGAN_RAW_RES, target_res: int = 256,
                 input_res: int = 64) -> tuple[np.ndarray, np.ndarray]:
    """Load, check, pad/crop and pool one pair -> (input (input_res^3) bool, target (target_res^3) bool).

    Raises:
        DataError: naming the file: see :func:`load_grid`, input/target shapes differ, or
            a grid without any occupied voxel.
    """
    inp = load_grid(pair.input_path)
    tgt = load_grid(pair.target_path)
    if inp.shape != tgt.shape:
        raise DataError(f"{pair.input_path}: shape {inp.shape} differs from its target "
                        f"{pair.target_path} {tgt.shape}")
    for path, grid in ((pair.input_path, inp), (pair.target_path, tgt)):
        if not grid.any():
            raise DataError(f"{path}: arr_0 is an all-empty grid (no occupied voxel)")
    if max(inp.shape) > raw_res + 8:
        raise DataError(f"{pair.input_path}: grid {inp.shape} is much larger than raw_res={raw_res}")
    inp, tgt = centre_fit(inp, raw_res), centre_fit(tgt, raw_res)
    return max_pool(inp, input_res), max_pool(tgt, target_res)


def assign_splits(pairs: list[RecganPair], categories, unseen_categories, val_fraction: float = 0.1,
                  seed: int = 0) -> list[tuple[str, RecganPair]]:
    """(split, pair) for every pair that belongs to a split; other categories are dropped (logged).

    A category with ``val_*`` folders: those are ``val``, every ``train_*`` pair is ``train``.
    Otherwise train -> train/val, val = about ``val_fraction`` of the category's train shape
    ids (seeded hash; at least one id stays in train), every view of a held-out id in every
    train view set (no id in both); a category with a single train id holds out views
    instead. test 125 -> test_same, test 216 -> test_cross, unseen categories -> test_unseen
    (125) / test_unseen_cross (216); unseen pairs in train or val folders are not used.
    """
    categories, unseen = set(categories), set(unseen_categories)
    dropped = sorted({p.category for p in pairs} - categories - unseen)
    if dropped:
        log.info("3D-RecGAN++ categories not used by this config: %s", dropped)
    out: list[tuple[str, RecganPair]] = []
    train_by_cat: dict[str, list[RecganPair]] = defaultdict(list)
    has_val = {p.category for p in pairs if p.split_kind == "val"}
    for p in pairs:
        if p.category in unseen:
            if p.split_kind == "test":
                out.append(("test_unseen" if p.view_set == "same" else "test_unseen_cross", p))
        elif p.category in categories:
            if p.split_kind == "val":
                out.append(("val", p))
            elif p.split_kind == "train" and p.category in has_val:
                out.append(("train", p))
            elif p.split_kind == "train":
                train_by_cat[p.category].append(p)
            else:
                out.append(("test_same" if p.view_set == "same" else "test_cross", p))
    for cat, ps in sorted(train_by_cat.items()):
        ids = sorted({p.shape_id for p in ps}, key=lambda i: stable_hash([seed, cat, i]))
        if len(ids) > 1:
            n_val = min(len(ids) - 1, max(1, round(val_fraction * len(ids)))) if val_fraction > 0 else 0
            val_ids = set(ids[:n_val])
            out += [("val" if p.shape_id in val_ids else "train", p) for p in ps]
        else:
            # same-view keys hash as before cross-view train folders were read (splits stay put)
            views = sorted({(p.view_set, p.view) for p in ps},
                           key=lambda v: stable_hash([seed, cat, v[1]] if v[0] == "same" else [seed, cat, *v]))
            n_val = min(len(views) - 1, max(1, round(val_fraction * len(views)))) if val_fraction > 0 else 0
            val_views = set(views[:n_val])
            out += [("val" if (p.view_set, p.view) in val_views else "train", p) for p in ps]
    order = {"train": 0, "val": 1, "test_same": 2, "test_cross": 3, "test_unseen": 4, "test_unseen_cross": 5}
    out.sort(key=lambda sp: (order[sp[0]], sp[1].category, sp[1].folder, sp[1].shape_id, sp[1].view))
    return out
