"""Shape-completion data: procedural depth voxels or the 3D-RecGAN++ release, one packed cache.

``CompletionDataModule(source="synth")`` generates procedural furniture (seen:
bench, chair, couch, table) and unseen categories (car, faucet, firearm, guitar,
monitor, plane), renders one depth view per sample and voxelises it like
3D-RecGAN++ (see :mod:`datamodules.completion.depth_voxels`).
``CompletionDataModule(source="recgan", root=PATH)`` converts the real release
(see :mod:`datamodules.completion.recgan`). ``source="meshes" | "shapenet" | "sweethome3d" | "installed"`` renders
real CAD models the procedural way (:mod:`datamodules.completion.meshes`). All write the same packed-bit cache
(:mod:`datamodules.completion.voxel_cache`) with a ``manifest.json`` into ``data_dir``; the item plan is
:mod:`datamodules.completion.plan`, each source's preparation :mod:`datamodules.completion.sources`.

Batches (default collate) are dicts:
    input    (B, 1, r, r, r) float32 {0,1}   r = target_res / input_factor
    target   (B, 1, R, R, R) float32 {0,1}   R = target_res
    label    (B,) int64  index into ``label_categories``: SEEN_CATEGORIES (lit3d.utils.shapenet_categories),
                         then the user categories of a folder of your own; -1 (unseen)
    category, split, name: list[str]
"""
from __future__ import annotations

import logging
from collections import Counter, defaultdict
from collections.abc import Mapping
from pathlib import Path

import lightning.pytorch as pl
import torch
from torch.utils.data import DataLoader

from datamodules.cache import CacheBuilder, DataError, bytes_on_disk
from datamodules.completion.catalogues import present_packages
from datamodules.completion.meshes import MESH_SOURCES, MeshSpec, folder_plan_categories, prepare_mesh_items
from datamodules.completion.plan import DEFAULT_SIZES, DataConfigError, ItemSpec, check_sizes
from datamodules.completion.recgan import RECGAN_RAW_RES
from datamodules.completion.settings import (CategorySettings, MeshSettings, PrepareSettings, RecganSettings,
                                             RenderSettings, parse)
from datamodules.completion.sources import prepare_recgan_items, prepare_synth_items
from datamodules.completion.voxel_cache import DATA_SPLITS, TEST_SPLITS, VoxelPairDataset, load_pair
from datamodules.loaders import evaluation_loader
from lit3d.sensing.sensor import SENSORS, make_sensor
from lit3d.utils.figures import labelled_grid
from lit3d.utils.shapenet_categories import (
    SEEN_CATEGORIES,
    UNSEEN_CATEGORIES,
    select_seen_categories,
    select_unseen_categories,
)
from lit3d.render.voxel_images import BACK_VIEW, FRONT_VIEW, render_voxels, to_resolution

log = logging.getLogger("lit3d.data")

SYNTH_VERSION = "1"
RECGAN_VERSION = "1"
MESHES_VERSION = "1"
DATA_SOURCES = ("synth", "recgan") + MESH_SOURCES

__all__ = ["DATA_SOURCES", "DEFAULT_SIZES", "CompletionDataModule", "DataConfigError"]


class CompletionDataModule(pl.LightningDataModule):
    """Shape-completion DataModule (see module docstring for the batch layout).

    Args:
        source: "synth" (procedural), "recgan" (the 3D-RecGAN++ release at ``root``) or a mesh source.
        data_dir: cache folder (manifest.json + items/<split>/*.npz).
        root: raw 3D-RecGAN++ folder (source=recgan) or the models' folder (mesh sources).
        target_res: R, the target grid (64 demo, 256 paper).
        input_factor: r = R / input_factor (4: 64 -> 16, 256 -> 64).
        sizes: synthetic items per split (train, val, test_same, test_cross, test_unseen,
            test_unseen_cross = unseen categories from the cross-view set, 0 when absent); splits
            left out keep the demo defaults (240/40/40/40/40); 0 drops a split.
        categories: ``{seen, unseen}`` (:class:`~datamodules.completion.settings.CategorySettings`). Labels
            index ``label_categories``: the seen thesis categories, then the seen user categories.
        render: ``{views_per_shape, unseen_view_set, render_factor, sensor}``
            (:class:`~datamodules.completion.settings.RenderSettings`).
        recgan: ``{val_fraction, raw_res}`` (:class:`~datamodules.completion.settings.RecganSettings`).
        meshes: ``{model_split, min_models, up_axis, procedural_share}``
            (:class:`~datamodules.completion.settings.MeshSettings`).
        prepare: ``{workers, progress, skip_bad, compress}``
            (:class:`~datamodules.completion.settings.PrepareSettings`).
    A data config of the flat layout of old: :func:`datamodules.completion.flat_config.upgrade_data_config`.
    """

    test_split_names: list[str]

    def __init__(self, *, target_res: int, source: str = "synth", data_dir: str = "data/completion_synth",
                 root: str | None = None, input_factor: int = 4, sizes: dict | None = None,
                 categories: Mapping | None = None, batch_size: int = 4, num_workers: int = 0, seed: int = 0,
                 pin_memory: bool = False, render: Mapping | None = None, recgan: Mapping | None = None,
                 meshes: Mapping | None = None, prepare: Mapping | None = None):
        super().__init__()
        if source not in DATA_SOURCES:
            raise DataConfigError(f"data.source={source!r}: expected one of {', '.join(DATA_SOURCES)}")
        if target_res % input_factor:
            raise DataConfigError(f"data.target_res={target_res} is not divisible by data.input_factor={input_factor}")
        cats = parse(CategorySettings, categories, "categories")
        render, recgan = parse(RenderSettings, render, "render"), parse(RecganSettings, recgan, "recgan")
        meshes, prepare = parse(MeshSettings, meshes, "meshes"), parse(PrepareSettings, prepare, "prepare")
        self.source, self.data_dir = source, Path(data_dir)
        self.root = None if root in (None, "") else Path(root)
        seen, unseen = cats.seen, cats.unseen
        if source == "meshes":  # a folder of your own: its category folders, thesis names or not
            seen, unseen = folder_plan_categories(self.root, seen, unseen)
        try:
            seen, unseen = (tuple(seen), tuple(unseen)) if source == "meshes" else (
                select_seen_categories(seen), select_unseen_categories(unseen))
        except ValueError as exc:  # "categories: ..." or "unseen_categories: ..."
            what, _, why = str(exc).partition(": ")
            raise DataConfigError(f"data.categories.{'unseen' if what.startswith('unseen') else 'seen'}: {why}") from None
        self.target_res, self.input_factor = int(target_res), int(input_factor)
        self.input_res = self.target_res // self.input_factor
        self.sizes = {**DEFAULT_SIZES, **check_sizes(sizes)}
        self.categories, self.unseen_categories = tuple(seen), tuple(unseen)
        # class labels: the thesis's seen categories, then the other seen ones (user categories), in plan order
        self.label_categories = SEEN_CATEGORIES + tuple(c for c in self.categories if c not in SEEN_CATEGORIES)
        self.user_categories = tuple(c for c in self.categories + self.unseen_categories
                                     if c not in SEEN_CATEGORIES + UNSEEN_CATEGORIES)
        self.batch_size, self.num_workers = int(batch_size), int(num_workers)
        self.seed, self.skip_bad, self.pin_memory = int(seed), bool(prepare.skip_bad), bool(pin_memory)
        self.views_per_shape, self.unseen_view_set = int(render.views_per_shape), render.unseen_view_set
        self.val_fraction, self.raw_res = float(recgan.val_fraction), int(recgan.raw_res or RECGAN_RAW_RES)
        self.compress, self.render_factor = bool(prepare.compress), int(render.render_factor)
        self.progress = bool(prepare.progress)
        if source == "recgan" and self.raw_res % self.target_res:
            raise DataConfigError(f"data.target_res={target_res} must divide data.recgan.raw_res={recgan.raw_res}")
        try:
            self.sensor = make_sensor(render.sensor)
        except (TypeError, ValueError) as exc:
            raise DataConfigError(f"data.render.sensor: {exc}") from None
        self.model_split = meshes.model_split
        self.min_models, self.up_axis = int(meshes.min_models), str(meshes.up_axis)
        self.procedural_share = float(meshes.procedural_share)
        self.prepare_workers = int(prepare.workers)
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
            if self.procedural_share:  # only when mixing: the caches of unmixed configs keep their hash
                cfg.update(procedural_share=self.procedural_share)
            if self.source == "installed":  # another package unpacked later makes another cache
                cfg.update(catalogues=present_packages(self.root))
        else:
            cfg.update(root=str(self.root.resolve()) if self.root else None, raw_res=self.raw_res,
                       val_fraction=self.val_fraction, skip_bad=self.skip_bad)
        return cfg

    def _builder(self) -> CacheBuilder:
        gen, ver = {"synth": ("completion_synth", SYNTH_VERSION), "recgan": ("completion_recgan", RECGAN_VERSION)}.get(
            self.source, (f"completion_{self.source}", MESHES_VERSION))
        return CacheBuilder(self.data_dir, gen, ver, self.cache_config())

    @property
    def spec(self) -> ItemSpec:
        """What decides the planned items and their bytes (synthetic and mesh sources; recgan uses
        its categories, seed, grid sizes and compression)."""
        return ItemSpec(self.sizes, self.categories, self.unseen_categories, self.seed, self.views_per_shape,
                        self.unseen_view_set, self.target_res, self.input_factor, self.render_factor, self.sensor,
                        self.compress)

    # ---------------------------------------------------------------- preparation
    def prepare_data(self) -> None:
        """Generate (synth), render (mesh sources) or convert (recgan) into ``data_dir``; no-op when
        the cache is complete (:meth:`~datamodules.cache.CacheBuilder.prepare_once`)."""
        if self.source == "recgan" and self.root is None:
            raise DataConfigError("data.source=recgan needs the 3D-RecGAN++ folder: set data.root=PATH")
        self._builder().prepare_once(self._prepare_items)

    def _prepare_items(self, builder: CacheBuilder) -> tuple[list[dict], dict]:
        if self.source == "synth":
            items, extra = prepare_synth_items(builder, self.spec, self.progress)
        elif self.source in MESH_SOURCES:
            mesh = MeshSpec(self.source, self.root, self.model_split, self.min_models, self.up_axis,
                            self.procedural_share)
            items, extra = prepare_mesh_items(builder, self.spec, mesh, self.skip_bad, self.prepare_workers,
                                              self.progress)
        else:
            items, extra = prepare_recgan_items(builder, self.spec, self.root, self.raw_res, self.val_fraction,
                                                self.skip_bad, self.progress)
        extra.update(target_res=self.target_res, input_res=self.input_res, seen_categories=list(self.label_categories))
        return items, extra

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
        self.datasets = {s: VoxelPairDataset(self.data_dir, by_split.get(s, []), self.label_categories) for s in DATA_SPLITS}
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
            **{k: m[k] for k in ("models_per_category", "models_used_per_split", "fallback", "small_categories") if k in m},
            **({"user_categories": list(self.user_categories), "label_categories": list(self.label_categories)}
               if self.user_categories else {}),
            **({"dropped_entries": len(m["dropped"])} if m.get("dropped") else {}),
        }

    def show(self, n: int, path: str | Path, cell: int = 256) -> Path:
        """PNG of ``n`` samples spread over the splits: per sample the input (nearest-upsampled to
        the target's grid) and the target as shaded marching-cubes renders
        (:func:`lit3d.render.voxel_images.render_voxels`), seen from the depth camera's side and
        from behind, ``cell`` px each, labelled with split, name and the input's fill."""
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
            label = (f"{s}\n{it['name']}{origin}\ninput {int(inp.sum())} of {inp.numel()} voxels"
                     f"\ntarget fill {float(tgt.mean()):.3f}")
            rows.append({"label": label, "cells": [views[0][0], views[1][0], views[0][1], views[1][1]]})
        if not rows:
            raise DataError(f"{self.data_dir}: no samples to show")
        sensor = ("3D-RecGAN++ files" if self.source == "recgan" else
                  self.sensor.camera + (", mirrored x" if self.sensor.mirror_x else "")
                  + (", noisy" if self.sensor.noisy else ""))
        title = f"Completion data ({self.source}, {sensor}): input {self.input_res}^3, target {self.target_res}^3"
        img = labelled_grid(rows, ["input, camera side", "target, camera side", "input, behind", "target, behind"],
                            title, cell, left=330)
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        img.save(path)
        return path
