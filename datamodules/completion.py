"""Shape-completion data: procedural depth voxels or the 3D-RecGAN++ release, one packed cache.

``CompletionDataModule(source="synth")`` generates procedural furniture (seen:
bench, chair, couch, table) and unseen categories (car, faucet, firearm, guitar,
monitor, plane), renders one depth view per sample and voxelises it like
3D-RecGAN++ (see :mod:`datamodules.synth.depth_voxels`).
``CompletionDataModule(source="recgan", root=PATH)`` converts the real release
(see :mod:`datamodules.readers.recgan`). ``source="meshes" | "shapenet" | "sweethome3d"`` renders
real CAD models the procedural way (:mod:`datamodules.completion_meshes`). Both write the same packed-bit cache
(:mod:`datamodules.voxel_cache`) with a ``manifest.json`` into ``data_dir``.

Batches (default collate) are dicts:
    input    (B, 1, r, r, r) float32 {0,1}   r = target_res / input_factor
    target   (B, 1, R, R, R) float32 {0,1}   R = target_res
    label    (B,) int64  index into SEEN_CATEGORIES (lit3d.utils.shapenet_categories) or -1 (unseen)
    category, split, name: list[str]
"""
from __future__ import annotations

import logging
from collections import Counter, defaultdict
from collections.abc import Sequence
from pathlib import Path

import lightning.pytorch as pl
import numpy as np
from torch.utils.data import DataLoader

from datamodules.cache import CacheBuilder, DataError, bytes_on_disk, stable_seed
from datamodules.completion_meshes import MESH_SOURCES
from datamodules.loaders import evaluation_loader
from datamodules.synth.sensor import SENSORS, make_sensor
from datamodules.voxel_cache import DATA_SPLITS, TEST_SPLITS, VoxelPairDataset, load_pair, save_pair
from lit3d.utils.shapenet_categories import (
    SEEN_CATEGORIES,
    select_seen_categories,
    select_unseen_categories,
)

log = logging.getLogger("lit3d.data")

DEFAULT_SIZES = {"train": 240, "val": 40, "test_same": 40, "test_cross": 40, "test_unseen": 40}
SYNTH_VERSION = "1"
RECGAN_VERSION = "1"
MESHES_VERSION = "1"
DATA_SOURCES = ("synth", "recgan") + MESH_SOURCES
DEFAULT_MODEL_SPLIT = {"train": 0.7, "val": 0.1, "test": 0.2}


class DataConfigError(DataError):
    """A data setting that cannot work (e.g. source=recgan without root)."""


# ---------------------------------------------------------------- synthetic item plan
def check_sizes(sizes: dict | None) -> dict:
    """``data.sizes`` as ``{split: int >= 0}``; an unknown split (``+data.sizes.trian=10``) or a
    count that is not a whole number >= 0 raises :class:`DataConfigError` listing the known splits,
    before any cache is touched (an unknown key would otherwise be dropped and change the cache hash)."""
    out = {}
    for k, v in dict(sizes or {}).items():
        if k not in DATA_SPLITS:
            raise DataConfigError(f"data.sizes.{k}: unknown split; known: {', '.join(DATA_SPLITS)}")
        n = 0 if v is None else v
        if isinstance(n, bool) or not isinstance(n, (int, float)) or n < 0 or n != int(n):
            raise DataConfigError(f"data.sizes.{k}={v!r}: expected a whole number of items >= 0")
        out[k] = int(n)
    return out


def synth_items(sizes: dict, categories: Sequence[str], unseen_categories: Sequence[str], seed: int,
                views_per_shape: int = 4, unseen_view_set: str = "same") -> list[dict]:
    """The plan of every synthetic item (cheap: no geometry), deterministic in ``seed``.

    Items cycle over the categories (balanced counts); the j-th item of a category
    shows shape ``j // views_per_shape`` of that category. Shape instances come from groups: train, val, test (shared by test_same
    and test_cross, as in 3D-RecGAN++ whose test_125/test_216 hold the same ids) and
    unseen. Views of one shape are distinct and drawn from the split's view set.
    """
    from datamodules.synth.depth_voxels import VIEW_SETS, view_index  # noqa: PLC0415

    items = []
    for split in DATA_SPLITS:
        n = int(sizes.get(split, 0) or 0)
        cats = list(unseen_categories) if split.startswith("test_unseen") else list(categories)
        if n <= 0 or not cats:
            continue
        group = {"test_same": "test", "test_cross": "test", "test_unseen": "unseen",
                 "test_unseen_cross": "unseen"}.get(split, split)
        view_set = {"test_cross": "cross", "test_unseen": unseen_view_set, "test_unseen_cross": "cross"}.get(split, "same")
        views = VIEW_SETS[view_set]
        for i in range(n):
            category = cats[i % len(cats)]
            j = i // len(cats)  # item number within the category
            shape_index = j // views_per_shape
            vrng = np.random.default_rng(stable_seed(seed, "views", split, category, shape_index))
            chosen = vrng.choice(len(views), size=min(views_per_shape, len(views)), replace=False)
            v = int(chosen[j % len(chosen)])
            a, b, c = view_index(view_set, v)
            name = f"{category}_{group}{shape_index:04d}_{a}_{b}_{c}"
            items.append({
                "name": name, "split": split, "category": category, "view_set": view_set,
                "shape_group": group, "shape_index": shape_index, "view": [float(x) for x in views[v]],
                "file": f"items/{split}/{name}.npz",
            })
    return items


def synth_pair(item: dict, seed: int, target_res: int, input_factor: int, render_factor: int = 2,
               sensor: str | dict | None = None):
    """Generate one planned synthetic item -> (input, target) bool grids.

    ``sensor``: :mod:`datamodules.synth.sensor` (name or fields; None = orthographic, noise-free);
    its noise is drawn from a generator seeded by ``seed`` and the item's name.
    """
    from datamodules.synth.furniture import make_shape  # noqa: PLC0415

    rng = np.random.default_rng(stable_seed(seed, "shape", item["shape_group"], item["category"], item["shape_index"]))
    return view_pair(make_shape(item["category"], rng), item, seed, target_res, input_factor, render_factor, sensor)


def view_pair(shape, item: dict, seed: int, target_res: int, input_factor: int, render_factor: int = 2,
              sensor: str | dict | None = None):
    """One planned item's view of ``shape`` (procedural or a real mesh) -> (input, target) bool grids;
    the sensor noise is drawn from a generator seeded by ``seed`` and the item's split and name."""
    from datamodules.synth.depth_voxels import make_sample  # noqa: PLC0415

    noise = np.random.default_rng(stable_seed(seed, "sensor", item["split"], item["name"]))
    out = make_sample(shape, tuple(item["view"]), target_res=target_res, input_factor=input_factor,
                      render_factor=render_factor, sensor=sensor, rng=noise)
    return out["input"], out["target"]


class CompletionDataModule(pl.LightningDataModule):
    """Shape-completion DataModule (see module docstring for the batch layout).

    Args:
        source: "synth" (procedural) or "recgan" (the 3D-RecGAN++ release at ``root``).
        data_dir: cache folder (manifest.json + items/<split>/*.npz).
        root: raw 3D-RecGAN++ folder (source=recgan only).
        target_res: R, the target grid (64 demo, 256 paper).
        input_factor: r = R / input_factor (4: 64 -> 16, 256 -> 64).
        sizes: synthetic items per split (train, val, test_same, test_cross, test_unseen,
            test_unseen_cross = unseen categories from the cross-view set, 0 when absent); splits
            left out keep the demo defaults (240/40/40/40/40); 0 drops a split.
        categories: seen categories used for train/val/test_same/test_cross (None: all of
            :data:`~lit3d.utils.shapenet_categories.SEEN_CATEGORIES`; labels always index that list).
        unseen_categories: categories of test_unseen / test_unseen_cross (None: all unseen categories).
        views_per_shape: synthetic views per shape instance.
        unseen_view_set: view set of synthetic test_unseen ("same" or "cross").
        val_fraction: recgan: share of train shape ids held out as val.
        raw_res: recgan: grids are centre-padded/cropped to raw_res^3 (256).
        skip_bad: recgan: skip bad files with a warning (count in describe()) instead of raising.
        compress: zlib-compress the packed bits (smaller; measured about as fast to load).
        render_factor: synth depth image size = render_factor * target_res.
        sensor: synth: camera, handedness and noise of the 2.5D input (:mod:`datamodules.synth.sensor`):
            "ortho" (orthographic, noise-free), "recgan" (3D-RecGAN++'s perspective camera and
            handedness, noise calibrated on its released sample), or a dict of Sensor fields.
        progress: tqdm progress bar during preparation.
    """

    test_split_names: list[str]

    def __init__(self, source: str = "synth", data_dir: str = "data/completion_synth", root: str | None = None,
                 target_res: int = 64, input_factor: int = 4, sizes: dict | None = None,
                 categories: Sequence[str] | None = None, unseen_categories: Sequence[str] | None = None,
                 batch_size: int = 4, num_workers: int = 0, seed: int = 0, skip_bad: bool = False,
                 pin_memory: bool = False, views_per_shape: int = 4, unseen_view_set: str = "same",
                 val_fraction: float = 0.1, raw_res: int = 256, compress: bool = True, render_factor: int = 2,
                 progress: bool = True, sensor: str | dict = "ortho", model_split: dict | None = None,
                 min_models: int = 8, up_axis: str = "y", prepare_workers: int = 0):
        super().__init__()
        if source not in DATA_SOURCES:
            raise DataConfigError(f"data.source={source!r}: expected one of {', '.join(DATA_SOURCES)}")
        if target_res % input_factor:
            raise DataConfigError(f"data.target_res={target_res} is not divisible by data.input_factor={input_factor}")
        try:
            categories, unseen_categories = select_seen_categories(categories), select_unseen_categories(unseen_categories)
        except ValueError as exc:
            raise DataConfigError(f"data.{exc}") from None
        self.source, self.data_dir = source, Path(data_dir)
        self.root = None if root in (None, "") else Path(root)
        self.target_res, self.input_factor = int(target_res), int(input_factor)
        self.input_res = self.target_res // self.input_factor
        self.sizes = {**DEFAULT_SIZES, **check_sizes(sizes)}
        self.categories, self.unseen_categories = tuple(categories), tuple(unseen_categories)
        self.batch_size, self.num_workers = int(batch_size), int(num_workers)
        self.seed, self.skip_bad, self.pin_memory = int(seed), bool(skip_bad), bool(pin_memory)
        self.views_per_shape, self.unseen_view_set = int(views_per_shape), unseen_view_set
        self.val_fraction, self.raw_res = float(val_fraction), int(raw_res)
        self.compress, self.render_factor, self.progress = bool(compress), int(render_factor), bool(progress)
        if source == "recgan" and self.raw_res % self.target_res:
            raise DataConfigError(f"data.target_res={target_res} must divide data.raw_res={raw_res}")
        try:
            self.sensor = make_sensor(dict(sensor) if hasattr(sensor, "keys") else sensor)
        except (TypeError, ValueError) as exc:
            raise DataConfigError(f"data.sensor: {exc}") from None
        self.model_split = {str(k): float(v) for k, v in dict(model_split or DEFAULT_MODEL_SPLIT).items()}
        if set(self.model_split) != set(DEFAULT_MODEL_SPLIT) or min(self.model_split.values()) < 0:
            raise DataConfigError(f"data.model_split={dict(model_split)}: expected fractions >= 0 for train, val and test")
        self.min_models, self.up_axis = int(min_models), str(up_axis)
        self.prepare_workers = int(prepare_workers)
        self.manifest: dict | None = None
        self.datasets: dict[str, VoxelPairDataset] = {}
        self.test_split_names = []

    # ---------------------------------------------------------------- config
    def cache_config(self) -> dict:
        """Everything that changes the cached bytes (its hash is the manifest's config hash)."""
        cfg = {"source": self.source, "target_res": self.target_res, "input_factor": self.input_factor,
               "categories": list(self.categories), "unseen_categories": list(self.unseen_categories),
               "seed": self.seed, "compress": self.compress}
        if self.source != "recgan":
            cfg.update(sizes={k: int(v) for k, v in sorted(self.sizes.items())}, views_per_shape=self.views_per_shape,
                       unseen_view_set=self.unseen_view_set, render_factor=self.render_factor)
            if self.sensor != SENSORS["ortho"]:  # the original data keeps its hash
                cfg.update(sensor=self.sensor.as_dict())
        if self.source in MESH_SOURCES:
            cfg.update(root=str(self.root.resolve()) if self.root else None, model_split=self.model_split,
                       min_models=self.min_models, up_axis=self.up_axis, skip_bad=self.skip_bad)
        else:
            cfg.update(root=str(self.root.resolve()) if self.root else None, raw_res=self.raw_res,
                       val_fraction=self.val_fraction, skip_bad=self.skip_bad)
        return cfg

    def _builder(self) -> CacheBuilder:
        gen, ver = {"synth": ("completion_synth", SYNTH_VERSION), "recgan": ("completion_recgan", RECGAN_VERSION)}.get(
            self.source, (f"completion_{self.source}", MESHES_VERSION))
        return CacheBuilder(self.data_dir, gen, ver, self.cache_config())

    # ---------------------------------------------------------------- preparation
    def prepare_data(self) -> None:
        """Generate (synth) or convert (recgan) into ``data_dir``; no-op when the cache is complete."""
        if self.source == "recgan" and self.root is None:
            raise DataConfigError("data.source=recgan needs the 3D-RecGAN++ folder: set data.root=PATH")
        builder = self._builder()
        if builder.is_complete():
            return
        with builder.locked():  # the jobs of a multirun may prepare one data_dir at once: one at a time
            if builder.is_complete():  # another process prepared it while this one waited
                return
            builder.begin()
            if self.source == "synth":
                items, extra = self._prepare_synth(builder)
            elif self.source in MESH_SOURCES:
                from datamodules.completion_meshes import prepare_mesh_items  # noqa: PLC0415

                items, extra = prepare_mesh_items(self, builder)
            else:
                items, extra = self._prepare_recgan(builder)
            extra.update(target_res=self.target_res, input_res=self.input_res,
                         seen_categories=list(SEEN_CATEGORIES))
            builder.finish(items, extra)

    def _progress(self, iterable, total: int, desc: str):
        from tqdm.auto import tqdm  # noqa: PLC0415

        return tqdm(iterable, total=total, desc=desc, unit="item", disable=not self.progress, dynamic_ncols=True)

    def _prepare_synth(self, builder: CacheBuilder) -> tuple[list[dict], dict]:
        items = synth_items(self.sizes, self.categories, self.unseen_categories, self.seed,
                            self.views_per_shape, self.unseen_view_set)
        todo = [it for it in items if not builder.has(it["file"])]
        if len(todo) < len(items):
            log.info("%s: %d of %d items already prepared", self.data_dir, len(items) - len(todo), len(items))
        for it in self._progress(todo, len(todo), "completion synth"):
            inp, tgt = synth_pair(it, self.seed, self.target_res, self.input_factor, self.render_factor, self.sensor)
            save_pair(builder.path(it["file"]), inp, tgt, compress=self.compress)
        return items, {"skipped": []}

    def _prepare_recgan(self, builder: CacheBuilder) -> tuple[list[dict], dict]:
        from datamodules.readers.recgan import assign_splits, convert_pair, index_recgan  # noqa: PLC0415

        pairs, problems = index_recgan(self.root, skip_bad=self.skip_bad)
        planned = assign_splits(pairs, self.categories, self.unseen_categories, self.val_fraction, self.seed)
        items = []
        for split, p in self._progress(planned, len(planned), "completion recgan"):
            it = {"name": p.name, "split": split, "category": p.category, "view_set": p.view_set,
                  "shape_id": p.shape_id, "view": p.view, "source_folder": p.folder,
                  "input_file": str(p.input_path.relative_to(self.root)),
                  "file": f"items/{split}/{p.name}_{p.view_set}.npz"}
            if not builder.has(it["file"]):
                try:
                    inp, tgt = convert_pair(p, self.raw_res, self.target_res, self.input_res)
                except DataError as exc:
                    if not self.skip_bad:
                        raise
                    log.warning("skipping: %s", exc)
                    problems.append(str(exc))
                    continue
                save_pair(builder.path(it["file"]), inp, tgt, compress=self.compress)
            items.append(it)
        if problems:
            log.warning("%s: skipped %d bad file(s)", self.root, len(problems))
        return items, {"skipped": problems}

    # ---------------------------------------------------------------- loading
    def setup(self, stage: str | None = None) -> None:
        """Read the manifest and build one dataset per split (prepare_data() must have run)."""
        builder = self._builder()
        manifest = builder.manifest()
        if manifest is None or manifest.get("config_hash") != builder.config_hash:
            raise DataError(f"{self.data_dir}: no prepared data for this config (run prepare_data() or lit3d-data)")
        self.manifest = manifest
        by_split: dict[str, list[dict]] = defaultdict(list)
        for it in manifest["items"]:
            by_split[it["split"]].append(it)
        self.datasets = {s: VoxelPairDataset(self.data_dir, by_split.get(s, []), SEEN_CATEGORIES) for s in DATA_SPLITS}
        self.test_split_names = [s for s in TEST_SPLITS if len(self.datasets[s])]

    def _loader(self, split: str, shuffle: bool) -> DataLoader:
        if not self.datasets:
            self.setup()
        if not shuffle:  # val/test: every item once, also under DDP
            return evaluation_loader(self.datasets[split], self.batch_size, self.num_workers,
                                     pin_memory=self.pin_memory, persistent_workers=self.num_workers > 0)
        return DataLoader(self.datasets[split], batch_size=self.batch_size, shuffle=shuffle,
                          num_workers=self.num_workers, pin_memory=self.pin_memory,
                          persistent_workers=self.num_workers > 0, drop_last=False)

    def train_dataloader(self) -> DataLoader:
        return self._loader("train", shuffle=True)

    def val_dataloader(self) -> DataLoader:
        return self._loader("val", shuffle=False)

    def test_dataloader(self) -> list[DataLoader]:
        """One loader per split in ``self.test_split_names`` (splits without items are left out)."""
        if not self.datasets:
            self.setup()
        return [self._loader(s, shuffle=False) for s in self.test_split_names]

    # ---------------------------------------------------------------- reporting
    def describe(self) -> dict:
        """Counts per split and category, grid sizes, bytes on disk, manifest hash."""
        if self.manifest is None:
            self.setup()
        m = self.manifest
        counts: dict[str, dict[str, int]] = {}
        for it in m["items"]:
            counts.setdefault(it["split"], Counter())[it["category"]] += 1
        return {
            "source": self.source, "data_dir": str(self.data_dir),
            "root": str(self.root) if self.root else None,
            "generator": m["generator"], "version": m["version"],
            "counts": {s: dict(sorted(c.items())) for s, c in counts.items()},
            "split_sizes": {s: sum(c.values()) for s, c in counts.items()},
            "input_shape": [1, self.input_res, self.input_res, self.input_res],
            "target_shape": [1, self.target_res, self.target_res, self.target_res],
            "bytes_on_disk": bytes_on_disk(self.data_dir, [it["file"] for it in m["items"]]),
            "manifest_hash": m["manifest_hash"], "config_hash": m["config_hash"],
            "skipped_bad_files": len(m.get("skipped", [])),
            "test_split_names": list(self.test_split_names),
            **{k: m[k] for k in ("models_per_category", "models_used_per_split", "fallback") if k in m},
        }

    def show(self, n: int, path: str | Path, cell: int = 256) -> Path:
        """PNG of ``n`` samples spread over the splits: per sample the input (nearest-upsampled to
        the target's grid) and the target as shaded marching-cubes renders
        (:func:`lit3d.utils.voxel_images.render_voxels`), seen from the depth camera's side and
        from behind, ``cell`` px each, labelled with split, name and the input's fill."""
        import torch  # noqa: PLC0415

        from lit3d.utils.figures import labelled_grid  # noqa: PLC0415
        from lit3d.utils.voxel_images import BACK_VIEW, FRONT_VIEW, render_voxels, to_resolution  # noqa: PLC0415

        if not self.datasets:
            self.setup()
        splits = [s for s in DATA_SPLITS if len(self.datasets[s])]
        picks = []
        for idx in range(max((len(self.datasets[s]) for s in splits), default=0)):
            picks += [(s, idx) for s in splits if idx < len(self.datasets[s])]
            if len(picks) >= n:
                break
        rows = []
        for s, idx in picks[:n]:
            it = self.datasets[s].items[idx]
            inp, tgt = (torch.from_numpy(a).float() for a in load_pair(self.data_dir / it["file"]))
            views = [render_voxels(v, 0.5, cell, (FRONT_VIEW, BACK_VIEW), style) for v, style in
                     ((to_resolution(inp, self.target_res), "matt_blue"), (tgt, "clay_brown"))]
            origin = f"\nmodel {it['model_id'].split('/')[-1]}" if it.get("model_id") else ""
            label = f"{s}\n{it['name']}{origin}\ninput {int(inp.sum())} of {inp.numel()} voxels\ntarget fill {float(tgt.mean()):.3f}"
            rows.append({"label": label, "cells": [views[0][0], views[1][0], views[0][1], views[1][1]]})
        if not rows:
            raise DataError(f"{self.data_dir}: no samples to show")
        sensor = "3D-RecGAN++ files" if self.source == "recgan" else self.sensor.camera + (", mirrored x" if self.sensor.mirror_x else "") + (", noisy" if self.sensor.noisy else "")
        title = f"Completion data ({self.source}, {sensor}): input {self.input_res}^3, target {self.target_res}^3"
        img = labelled_grid(rows, ["input, camera side", "target, camera side", "input, behind", "target, behind"],
                            title, cell, left=330)
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        img.save(path)
        return path
