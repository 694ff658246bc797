"""Shape-quality data (thesis ch. 4): mesh pairs -> cached feature tables -> a feature matrix.

Two sources:

- ``source="synth"`` (default, no download): procedural reference shapes (plus every
  mesh in ``synth.user_mesh_dir``) x distortion types x levels (``datamodules.quality.distortions``).
  The target is the **ordinal severity score** of the distortion level within its
  type, ``(level + 1) / n_levels`` in (0, 1]: a rank that the generator knows, *not*
  a human opinion score. It only says "level 3 of smoothing is worse than level 2 of
  smoothing"; how smoothing compares with noise is a convention of this set.
- ``source="liris_epfl" | "liris_masking" | "guo2016"``: the human-rated datasets, read
  from ``root`` in their published layout (``datamodules.quality.mos``). Target: the
  mean opinion score (MOS).
- ``source="mos_folder"``: a human-rated set of your own, ``root/<shape>/<stimulus>`` meshes or
  point clouds plus one score table (``datamodules.quality.mos_folder``); ``score_range`` and
  ``higher_is_better`` say how its score reads.
- ``source="cpcd2"``: coloured point clouds in the CPCD2.0 layout (zipped ASCII PLY +
  ``mos.csv``, ``datamodules.quality.cpcd2``); the clouds are rendered as points.

Either way targets are oriented "higher = more distorted" and scaled to [0, 1] with
the dataset's published range (:class:`lit3d.features.matrix.TargetScaling`).

``prepare_data()`` fills ``data_dir/<config hash>/`` through :class:`datamodules.cache.CacheBuilder`
(atomic, resumable; ``manifest.json`` with generator, version, config hash and the sha256 of
every item file): the distorted meshes (synth only), one feature table per pair
(``features/<shape>__<name>.json``: ``name -> float``, :mod:`datamodules.quality.features`,
computed by ``lit3d.features.table`` in ``feature_tables.workers`` processes), then ``matrix.npz`` (the
:class:`FeatureMatrix`) and ``pairs.json``. ``setup()`` reads it and splits by group:
``split.test_shapes`` / ``split.val_shapes`` are held out, the rest trains (``[]``: none held out; ``None``: the
last group, and for validation the one before it). The groups (``split.groups``) are the reference
shapes, or with ``split.groups="family"`` the distortion families of CPCD2-style stimulus names
(``<cloud>_<family>_<n>``: :func:`datamodules.quality.cpcd2.stimulus_family`).

Batches (:mod:`datamodules.quality.batches`): ``{"x": (B, F) float32 all features, "y": (B,)
float32 in [0, 1], "shape_id": (B,) int64 into ``shape_names``, "shape": list[str], "item":
list[str]}``; the task picks its selected columns. Training batches follow
:class:`~datamodules.quality.batches.ShuffledBatches` (seed ``seed``).
"""
from __future__ import annotations

import json
import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import lightning.pytorch as pl
import numpy as np
import torch
import trimesh
from torch.utils.data import DataLoader, SequentialSampler

from datamodules.cache import (
    CacheBuilder,
    DataError,
    atomic_save_npz,
    stable_int_seed,
    write_json,
)
from datamodules.loaders import evaluation_loader
from datamodules.quality.batches import QualityPairDataset, ShuffledBatches
from datamodules.quality.cpcd2 import read_cpcd2, stimulus_family
from datamodules.quality.features import (  # noqa: F401  (re-exported)
    FeatureFn,
    feature_file,
    resolve_feature_fn,
    write_feature_tables,
)
from datamodules.quality.mos import read_mos_dataset
from datamodules.quality.mos_folder import read_mos_folder
from datamodules.quality.preview import mesh_pairs_png
from datamodules.quality.settings import FeatureSettings, SplitSettings, SynthSettings, parse
from datamodules.quality.distortions import LEVELS, distort, severity
from datamodules.quality.quality_shapes import (  # noqa: F401  (re-exported)
    MESH_SUFFIXES,
    PROCEDURAL_SHAPES,
    load_user_meshes,
    procedural_shape,
)
from lit3d.features.matrix import FeatureMatrix, TargetScaling, clip_nonfinite
from lit3d.utils.io import atomic_write_bytes
from lit3d.utils.stops import check_stop

GENERATOR = "quality"
GENERATOR_VERSION = "quality-synth-3"
SEVERITY_NAME = "ordinal severity score"


class QualityDataModule(pl.LightningDataModule):
    """Mesh pairs + feature tables for the quality task (module docstring)."""

    def __init__(
        self,
        data_dir: str,
        source: str = "synth",
        seed: int = 0,
        batch_size: int = 3,
        num_workers: int = 0,
        synth: Mapping | None = None,
        # real sets
        root: str | None = None,
        spreadsheet: str | None = None,
        sheet: str | int | None = None,
        score_range: Sequence[float | None] | None = None,
        higher_is_better: bool | None = None,
        skip_bad: bool = False,
        feature_tables: Mapping | None = None,
        split: Mapping | None = None,
        name: str | None = None,
    ):
        """``synth``, ``feature_tables``, ``split``: the nodes of :mod:`datamodules.quality.settings` (None: the
        defaults); a data config of the flat layout of old: :func:`datamodules.quality.flat_config.upgrade_data_config`."""
        super().__init__()
        self.save_hyperparameters()
        self.synth_settings = parse(SynthSettings, synth, "synth")
        self.feature_settings = parse(FeatureSettings, feature_tables, "feature_tables")
        self.split_settings = parse(SplitSettings, split, "split")
        self.data_dir = Path(data_dir)
        self.source = source
        self.name = name or source
        self.batch_size = int(batch_size)
        self.num_workers = int(num_workers)
        self.matrix: FeatureMatrix | None = None
        self.scaling: TargetScaling | None = None
        self.splits: dict[str, FeatureMatrix] = {}
        self.sources: dict[str, dict] = {}
        self.manifest: dict | None = None
        self.skipped: list[str] = []  # bad rows / pairs skipped (skip_bad=True)

    # ------------------------------------------------------------ config
    def _levels(self) -> dict[str, list[float]]:
        hp = self.synth_settings
        table = {k: list(v) for k, v in (hp.levels or LEVELS).items()}
        unknown = [d for d in hp.distortions if d not in table]
        if unknown:
            raise KeyError(f"unknown distortion(s) {unknown} (known: {', '.join(table)})")
        out = {d: table[d] for d in hp.distortions}
        if hp.n_levels is not None:  # keep n levels spread from mildest to strongest
            for d, vals in out.items():
                idx = np.unique(np.round(np.linspace(0, len(vals) - 1, int(hp.n_levels))).astype(int))
                out[d] = [vals[i] for i in idx]
        return out

    def manifest_config(self) -> dict:
        """Everything that changes the cached files (hashed into the cache folder's name)."""
        hp, feats, synth = self.hparams, self.feature_settings, self.synth_settings
        cfg = {"source": self.source, "feature_fn": feats.fn, "feature_options": dict(feats.options)}
        if self.source == "synth":
            cfg.update({"shapes": list(synth.shapes), "user_mesh_dir": synth.user_mesh_dir, "levels": self._levels(),
                        "subdivisions": synth.subdivisions, "seed": int(hp.seed)})
            if synth.user_mesh_dir:  # user meshes merged by position (caches of split ones are stale)
                cfg["user_meshes"] = "merged_by_position"
        else:
            cfg.update({"root": str(hp.root), "spreadsheet": hp.spreadsheet, "sheet": hp.sheet,
                        "score_range": list(hp.score_range) if hp.score_range else None,
                        "higher_is_better": hp.higher_is_better})
        return cfg

    def cache_builder(self) -> CacheBuilder:
        config = self.manifest_config()
        probe = CacheBuilder(self.data_dir, GENERATOR, GENERATOR_VERSION, config)
        return CacheBuilder(self.data_dir / probe.config_hash[:12], GENERATOR, GENERATOR_VERSION, config,
                            items_dir="features")

    @property
    def config_hash(self) -> str:
        """sha256 of generator, version and :meth:`manifest_config` (its first 12 digits name the folder)."""
        return self.cache_builder().config_hash

    @property
    def cache_dir(self) -> Path:
        return self.cache_builder().root

    # ------------------------------------------------------------ pairs
    def _synth_pairs(self) -> list[dict]:
        """Write reference + distorted meshes (atomic, skip existing); one record per pair."""
        hp, synth = self.hparams, self.synth_settings
        refs = {s: procedural_shape(s, synth.subdivisions, hp.seed) for s in synth.shapes}
        if synth.user_mesh_dir:
            for k, m in load_user_meshes(synth.user_mesh_dir).items():
                if k in refs:
                    raise ValueError(f"user mesh '{k}' has the name of a procedural shape; rename the file")
                refs[k] = m
        mesh_dir = self.cache_dir / "meshes"
        pairs = []
        levels = self._levels()
        for shape, ref in refs.items():
            ref_path = mesh_dir / shape / "reference.ply"
            if not ref_path.is_file():
                atomic_write_bytes(ref_path, trimesh.exchange.ply.export_ply(ref, encoding="binary"))
            for kind, vals in levels.items():
                for level in range(len(vals)):
                    path = mesh_dir / shape / f"{kind}_{level + 1}.ply"
                    check_stop()  # Ctrl-C or SIGTERM: stop before the next mesh (lit3d.utils.stops)
                    if not path.is_file():
                        out = distort(ref, kind, level, stable_int_seed(hp.seed, shape, kind, level), levels)
                        atomic_write_bytes(path, trimesh.exchange.ply.export_ply(out, encoding="binary"))
                    pairs.append({"item": f"{shape}/{kind}_{level + 1}", "shape": shape, "reference": str(ref_path),
                                  "distorted": str(path), "score": severity(kind, level, levels),
                                  "distortion": kind, "level": level + 1})
        return pairs

    def _real_pairs(self) -> tuple[list[dict], TargetScaling]:
        hp = self.hparams
        if not hp.root:
            raise DataError(f"data source '{self.source}' needs data.root=PATH (the unpacked dataset folder)")
        kw = dict(spreadsheet=hp.spreadsheet, sheet=hp.sheet, on_error="skip" if hp.skip_bad else "raise",
                  score_range=tuple(hp.score_range) if hp.score_range else None)
        if self.source == "mos_folder":
            ds = read_mos_folder(hp.root, higher_is_better=hp.higher_is_better, name=self.name, **kw)
        else:
            ds = read_cpcd2(hp.root, **kw) if self.source == "cpcd2" else read_mos_dataset(hp.root, self.source, **kw)
        self.skipped += ds.skipped
        for p in ds.unrated:
            warnings.warn(f"{p}: mesh not rated in {ds.spreadsheet.name} (ignored)", stacklevel=2)
        lo, hi = ds.score_range()
        hib = ds.layout.higher_is_better if hp.higher_is_better is None else bool(hp.higher_is_better)
        pairs = [{"item": f"{it.shape}/{it.name}", "shape": it.shape, "reference": str(it.reference),
                  "distorted": str(it.distorted), "score": it.score, "distortion": None, "level": None}
                 for it in ds.items]
        return pairs, TargetScaling(lo, hi, hib, ds.layout.target_name)

    # ------------------------------------------------------------ prepare
    def prepare_data(self) -> None:
        """Meshes (synth), feature tables and the feature matrix into :attr:`cache_dir`; no-op when
        cached (:meth:`~datamodules.cache.CacheBuilder.prepare_once`)."""
        self.cache_builder().prepare_once(self._write_tables)

    def _write_tables(self, builder: CacheBuilder) -> tuple[list[dict], dict]:
        if self.source == "synth":
            pairs = self._synth_pairs()
            scaling = TargetScaling(0.0, 1.0, False, SEVERITY_NAME)
        else:
            pairs, scaling = self._real_pairs()
        feats = self.feature_settings
        builder.total_items = len(pairs)  # feature tables: what a Ctrl-C's stop line counts
        tables, pairs, skipped = write_feature_tables(builder.root, pairs, feats.fn, feats.options,
                                                      int(feats.workers), bool(self.hparams.skip_bad))
        self.skipped += skipped
        raw = np.array([p["score"] for p in pairs], dtype=np.float64)
        fm = FeatureMatrix.from_tables(tables, [p["shape"] for p in pairs], scaling.forward(raw),
                                       [p["item"] for p in pairs], dataset=self.name, target_name=scaling.name)
        atomic_save_npz(builder.path("matrix.npz"), compress=False, X=fm.X, names=np.array(fm.names),
                        shapes=fm.shapes, target=fm.target, items=np.array(fm.items), raw_score=raw)
        write_json(builder.path("pairs.json"), pairs)
        items = [{"file": feature_file(p["item"]), "item": p["item"], "shape": p["shape"]} for p in pairs]
        return items + [{"file": "matrix.npz"}, {"file": "pairs.json"}], {
            "scaling": scaling.to_dict(), "target_name": scaling.name, "n_pairs": len(pairs),
            "n_features": len(fm.names), "dataset": self.name, "skipped": self.skipped}

    # ------------------------------------------------------------ setup
    def load_matrix(self) -> FeatureMatrix:
        """The cached :class:`FeatureMatrix` (prepared first when missing); sets ``scaling``,
        ``skipped`` and ``sources`` (item -> pair record) from the manifest."""
        builder = self.cache_builder()
        if not builder.is_complete():
            self.prepare_data()
        with np.load(builder.path("matrix.npz"), allow_pickle=False) as z:
            fm = FeatureMatrix(clip_nonfinite(z["X"]), [str(n) for n in z["names"]], z["shapes"], z["target"],
                               [str(i) for i in z["items"]], self.name)
        manifest = builder.manifest()
        self.manifest = manifest
        self.skipped = list(manifest.get("skipped", []))
        self.scaling = TargetScaling.from_dict(manifest["scaling"])
        fm.target_name = self.scaling.name
        self.sources = {p["item"]: p for p in json.loads(builder.path("pairs.json").read_text())}
        return fm

    def setup(self, stage: str | None = None) -> None:
        if self.matrix is not None:
            return
        fm = self.load_matrix()
        split = self.split_settings
        if split.groups == "family":
            fm = FeatureMatrix(fm.X, fm.names, np.array([stimulus_family(i.split("/")[-1]) for i in fm.items]),
                               fm.target, fm.items, fm.dataset, fm.target_name)
        self.matrix = fm
        names = fm.shape_names
        test = list(split.test_shapes) if split.test_shapes is not None else names[-1:]
        val = list(split.val_shapes) if split.val_shapes is not None else (
            [s for s in names if s not in test][-1:] if len(names) > 2 else [])
        for s in test + val:
            if s not in names:
                raise KeyError(f"{self.name}: no shape '{s}' (shapes: {', '.join(names)})")
        train = [s for s in names if s not in test and s not in val]
        if not train:
            raise ValueError(f"{self.name}: no training shapes left (test={test}, val={val})")
        isin = lambda ss: np.isin(fm.shapes, ss)  # noqa: E731
        self.splits = {"train": fm.rows(isin(train)), "val": fm.rows(isin(val or test)), "test": fm.rows(isin(test))}

    @property
    def feature_names(self) -> list[str]:
        self.setup()
        return self.matrix.names

    @property
    def shape_names(self) -> list[str]:
        """Every shape of the dataset, sorted: the names behind the batches' ``shape_id``."""
        self.setup()
        return self.matrix.shape_names

    def split(self, name: str) -> FeatureMatrix:
        self.setup()
        return self.splits[name]

    def _loader(self, split: str, shuffle: bool) -> DataLoader:
        ds = QualityPairDataset(self.split(split), self.shape_names)
        # a seeded generator also for evaluation: making an iterator then draws nothing from torch's global RNG
        generator = torch.Generator().manual_seed(int(self.hparams.seed))
        if shuffle:
            batches = ShuffledBatches(SequentialSampler(ds), self.batch_size, seed=int(self.hparams.seed))
            return DataLoader(ds, batch_sampler=batches, num_workers=self.num_workers, generator=generator)
        return evaluation_loader(ds, batch_size=max(len(ds), 1), num_workers=self.num_workers, generator=generator)

    def train_dataloader(self) -> DataLoader:
        return self._loader("train", True)

    def val_dataloader(self) -> DataLoader:
        return self._loader("val", False)

    def test_dataloader(self) -> DataLoader:
        return self._loader("test", False)

    def predict_dataloader(self) -> DataLoader:
        return self._loader("test", False)

    # ------------------------------------------------------------ describe / show
    def describe(self) -> dict:
        self.setup()
        fm = self.matrix
        info: dict[str, Any] = {
            "dataset": self.name, "source": self.source, "target": fm.target_name,
            "target_note": ("ordinal severity of the distortion level within its type, (level+1)/n_levels; "
                            "NOT a human opinion score") if self.source == "synth" else
                           "mean opinion score, scaled to [0,1], higher = more distorted",
            "pairs": len(fm), "features": len(fm.names), "manifest_hash": self.manifest["manifest_hash"],
            "config_hash": self.manifest["config_hash"], "skipped_bad_files": len(self.skipped),
            "cache_dir": str(self.cache_dir),
            "splits": {k: {"pairs": len(v), "shapes": v.shape_names} for k, v in self.splits.items()},
            "pairs_per_shape": {s: int((fm.shapes == s).sum()) for s in fm.shape_names},
        }
        kinds = [p.get("distortion") for p in self.sources.values() if p.get("distortion")]
        if kinds:
            info["pairs_per_distortion"] = {k: kinds.count(k) for k in dict.fromkeys(kinds)}
        return info

    def show(self, n: int, path: str | Path) -> Path:
        """PNG: up to ``n`` pairs as depth-shaded silhouettes (reference | distorted) with their target."""
        self.setup()
        return mesh_pairs_png(self.matrix, self.sources, n, path)
