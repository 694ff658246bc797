"""Shape-quality data (thesis ch. 4): mesh pairs -> cached feature tables -> a feature matrix.

Two sources:

- ``source="synth"`` (default, no download): procedural reference shapes (plus every
  mesh in ``user_mesh_dir``) x distortion types x levels (``lit3d.quality.distortions``).
  The target is the **ordinal severity score** of the distortion level within its
  type, ``(level + 1) / n_levels`` in (0, 1]: a rank that the generator knows, *not*
  a human opinion score. It only says "level 3 of smoothing is worse than level 2 of
  smoothing"; how smoothing compares with noise is a convention of this set.
- ``source="liris_epfl" | "liris_masking" | "guo2016"``: the human-rated datasets, read
  from ``root`` in their published layout (``datamodules.readers.mos``). Target: the
  mean opinion score (MOS).

Either way targets are oriented "higher = more distorted" and scaled to [0, 1] with
the dataset's published range (:class:`lit3d.quality.protocol.TargetScaling`).

``prepare_data()`` writes (atomically, resumable, with ``manifest.json`` = generator
version + config hash) the distorted meshes (synth only) and one feature table per
pair (``features/<item>.json``: ``name -> float``) computed by
``lit3d.quality.features`` (the renderer's measures) in ``feature_workers``
processes, then ``matrix.npz`` (the :class:`FeatureMatrix`). ``setup()`` reads it
and splits by shape: ``test_shapes`` / ``val_shapes`` are held out, the rest trains.

Batches: ``{"x": (B, F) float32 all features, "y": (B,) float32 in [0, 1],
"shape": list[str], "item": list[str]}``; the task picks its selected columns.
"""
from __future__ import annotations

import hashlib
import json
import math
import os
import warnings
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import lightning.pytorch as pl
import numpy as np
import torch
import trimesh
from torch.utils.data import DataLoader, Dataset

from datamodules.cache import DataError
from lit3d.quality.distortions import DISTORTIONS, LEVELS, distort, severity, stable_seed
from lit3d.quality.protocol import FeatureMatrix, TargetScaling, clip_nonfinite
from lit3d.utils.io import atomic_write_bytes, atomic_write_text, write_json

GENERATOR_VERSION = "quality-synth-2"
SEVERITY_NAME = "ordinal severity score"
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
    rng = np.random.default_rng(stable_seed("shape", name, seed))
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


def load_user_meshes(folder: str | Path) -> dict[str, trimesh.Trimesh]:
    """Every mesh file in ``folder`` (name = file stem); one clear error per unreadable file."""
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
        if not isinstance(m, trimesh.Trimesh) or len(m.faces) == 0:
            raise ValueError(f"{p}: empty mesh (no faces)")
        out[p.stem] = m
    if not out:
        raise ValueError(f"{folder}: no mesh files ({', '.join(MESH_SUFFIXES)})")
    return out


# --------------------------------------------------------------------------- features
FeatureFn = Callable[[Path, Path], Mapping[str, float]]


def feature_config(options: Mapping[str, Any] | None = None):
    """``lit3d.quality.features.FeatureConfig`` from plain options (see
    :func:`lit3d.quality.features.feature_config`; imported lazily: the renderer is heavy)."""
    from lit3d.quality.features import feature_config as from_options

    return from_options(options)


def resolve_feature_fn(spec: str | None, options: Mapping[str, Any] | None = None) -> FeatureFn:
    """``None`` -> the renderer's cached feature table (``lit3d.quality.features.feature_table``
    with :func:`feature_config` of ``options``; ``options["cache_dir"]`` = its JSON cache);
    else a dotted path to ``fn(ref_path, dist_path, **options) -> dict``."""
    options = dict(options or {})
    if spec is None:
        from lit3d.quality.features import feature_table

        cfg = feature_config(options)
        cache_dir = options.get("cache_dir")

        def fn(ref: Path, dist: Path) -> Mapping[str, float]:
            return feature_table(ref, dist, cfg, cache_dir=cache_dir).features

        return fn
    import importlib

    module, _, name = spec.replace(":", ".").rpartition(".")
    target = getattr(importlib.import_module(module), name)
    return lambda ref, dist: target(ref, dist, **options)


def _feature_job(args: tuple) -> tuple[str, str | None]:
    """Worker: compute one pair's feature table and write it atomically; returns (item, error)."""
    item, ref, dist, out_path, spec, options = args
    try:
        table = dict(resolve_feature_fn(spec, options)(Path(ref), Path(dist)))
        atomic_write_text(out_path, json.dumps({k: float(v) for k, v in table.items()}, sort_keys=True))
        return item, None
    except Exception as exc:  # reported by the parent with the item name
        return item, f"{type(exc).__name__}: {exc}"


# --------------------------------------------------------------------------- dataset
class PairDataset(Dataset):
    """Rows of a :class:`FeatureMatrix` as dicts (see module docstring)."""

    def __init__(self, fm: FeatureMatrix):
        self.fm = fm
        self.x = torch.as_tensor(fm.X, dtype=torch.float32)
        self.y = torch.as_tensor(fm.target, dtype=torch.float32)

    def __len__(self) -> int:
        return len(self.fm)

    def __getitem__(self, i: int) -> dict:
        return {"x": self.x[i], "y": self.y[i], "shape": str(self.fm.shapes[i]), "item": self.fm.items[i]}


def _config_hash(cfg: Mapping[str, Any]) -> str:
    return hashlib.sha1(json.dumps(cfg, sort_keys=True, default=str).encode()).hexdigest()[:12]


class QualityDataModule(pl.LightningDataModule):
    """Mesh pairs + feature tables for the quality task (module docstring)."""

    def __init__(
        self,
        data_dir: str,
        source: str = "synth",
        seed: int = 0,
        batch_size: int = 3,
        num_workers: int = 0,
        # synthetic set
        shapes: Sequence[str] = PROCEDURAL_SHAPES,
        user_mesh_dir: str | None = None,
        distortions: Sequence[str] = DISTORTIONS,
        levels: Mapping[str, Sequence[float]] | None = None,
        n_levels: int | None = None,
        subdivisions: int = 4,
        # real sets
        root: str | None = None,
        spreadsheet: str | None = None,
        sheet: str | int | None = None,
        score_range: Sequence[float | None] | None = None,
        higher_is_better: bool | None = None,
        skip_bad: bool = False,
        # features
        feature_fn: str | None = None,
        feature_options: Mapping[str, Any] | None = None,
        feature_workers: int = 0,
        # splits
        test_shapes: Sequence[str] | None = None,
        val_shapes: Sequence[str] | None = None,
        name: str | None = None,
    ):
        super().__init__()
        self.save_hyperparameters()
        self.data_dir = Path(data_dir)
        self.source = source
        self.name = name or source
        self.batch_size = int(batch_size)
        self.num_workers = int(num_workers)
        self.matrix: FeatureMatrix | None = None
        self.scaling: TargetScaling | None = None
        self.splits: dict[str, FeatureMatrix] = {}
        self.sources: dict[str, dict] = {}
        self.skipped: list[str] = []  # bad rows / pairs skipped (skip_bad=True)

    # ------------------------------------------------------------ config
    def _levels(self) -> dict[str, list[float]]:
        hp = self.hparams
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
        hp = self.hparams
        cfg = {"generator_version": GENERATOR_VERSION, "source": self.source, "feature_fn": hp.feature_fn, "feature_options": dict(hp.feature_options or {})}
        if self.source == "synth":
            cfg.update({"shapes": list(hp.shapes), "user_mesh_dir": hp.user_mesh_dir, "levels": self._levels(),
                        "subdivisions": hp.subdivisions, "seed": int(hp.seed)})
        else:
            cfg.update({"root": str(hp.root), "spreadsheet": hp.spreadsheet, "sheet": hp.sheet,
                        "score_range": list(hp.score_range) if hp.score_range else None,
                        "higher_is_better": hp.higher_is_better})
        return cfg

    @property
    def config_hash(self) -> str:
        return _config_hash(self.manifest_config())

    @property
    def cache_dir(self) -> Path:
        return self.data_dir / self.config_hash

    # ------------------------------------------------------------ pairs
    def _synth_pairs(self) -> list[dict]:
        """Write reference + distorted meshes (atomic, skip existing); one record per pair."""
        hp = self.hparams
        refs = {s: procedural_shape(s, hp.subdivisions, hp.seed) for s in hp.shapes}
        if hp.user_mesh_dir:
            for k, m in load_user_meshes(hp.user_mesh_dir).items():
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
                    if not path.is_file():
                        out = distort(ref, kind, level, stable_seed(hp.seed, shape, kind, level), levels)
                        atomic_write_bytes(path, trimesh.exchange.ply.export_ply(out, encoding="binary"))
                    pairs.append({"item": f"{shape}/{kind}_{level + 1}", "shape": shape, "reference": str(ref_path),
                                  "distorted": str(path), "score": severity(kind, level, levels),
                                  "distortion": kind, "level": level + 1})
        return pairs

    def _real_pairs(self) -> tuple[list[dict], TargetScaling]:
        from datamodules.readers.mos import read_mos_dataset

        hp = self.hparams
        if not hp.root:
            raise DataError(f"data source '{self.source}' needs data.root=PATH (the unpacked dataset folder)")
        ds = read_mos_dataset(hp.root, self.source, spreadsheet=hp.spreadsheet, sheet=hp.sheet,
                              score_range=tuple(hp.score_range) if hp.score_range else None,
                              on_error="skip" if hp.skip_bad else "raise")
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
        matrix_path = self.cache_dir / "matrix.npz"
        if matrix_path.is_file() and (self.cache_dir / "manifest.json").is_file():
            return
        if self.source == "synth":
            pairs = self._synth_pairs()
            scaling = TargetScaling(0.0, 1.0, False, SEVERITY_NAME)
        else:
            pairs, scaling = self._real_pairs()
        tables, pairs = self._feature_tables(pairs)
        shapes = [p["shape"] for p in pairs]
        items = [p["item"] for p in pairs]
        raw = np.array([p["score"] for p in pairs], dtype=np.float64)
        fm = FeatureMatrix.from_tables(tables, shapes, scaling.forward(raw), items, dataset=self.name,
                                       target_name=scaling.name)
        import io

        buf = io.BytesIO()
        np.savez(buf, X=fm.X, names=np.array(fm.names), shapes=fm.shapes, target=fm.target,
                 items=np.array(fm.items), raw_score=raw)
        atomic_write_bytes(matrix_path, buf.getvalue())
        write_json(self.cache_dir / "pairs.json", pairs)
        write_json(self.cache_dir / "manifest.json", {
            "generator_version": GENERATOR_VERSION, "config": self.manifest_config(), "config_hash": self.config_hash,
            "scaling": scaling.to_dict(), "target_name": scaling.name, "n_pairs": len(pairs),
            "n_features": len(fm.names), "dataset": self.name, "skipped": self.skipped})

    def _feature_path(self, item: str) -> Path:
        return self.cache_dir / "features" / (item.replace("/", "__") + ".json")

    def _feature_tables(self, pairs: list[dict]) -> tuple[list[dict], list[dict]]:
        """Feature table of every pair (computed unless cached) and the pairs kept.

        Each table is written atomically as soon as it is computed, so an interrupted run
        resumes with the pairs still missing. A pair whose meshes fail raises :class:`DataError`
        (naming the item and the file), or is skipped with a warning when ``skip_bad``.
        """
        hp = self.hparams
        jobs = [(p["item"], p["reference"], p["distorted"], str(self._feature_path(p["item"])), hp.feature_fn,
                 dict(hp.feature_options or {})) for p in pairs if not self._feature_path(p["item"]).is_file()]
        workers = int(hp.feature_workers)
        if jobs and workers > 1:
            with ProcessPoolExecutor(workers) as ex:
                results = list(ex.map(_feature_job, jobs))
        else:
            results = [_feature_job(j) for j in jobs]
        errors = {i: f"{i}: {e}" for i, e in results if e}
        if errors and not hp.skip_bad:
            raise DataError(f"feature extraction failed for {len(errors)} pair(s); first: {next(iter(errors.values()))}")
        for msg in errors.values():
            warnings.warn(f"skipping pair {msg}", stacklevel=2)
        self.skipped += list(errors.values())
        kept = [p for p in pairs if p["item"] not in errors]
        if not kept:
            raise DataError(f"{self.cache_dir}: no pair left after skipping {len(errors)} bad one(s)")
        return [json.loads(self._feature_path(p["item"]).read_text()) for p in kept], kept

    # ------------------------------------------------------------ setup
    def load_matrix(self) -> FeatureMatrix:
        path = self.cache_dir / "matrix.npz"
        if not path.is_file():
            self.prepare_data()
        with np.load(path, allow_pickle=False) as z:
            fm = FeatureMatrix(clip_nonfinite(z["X"]), [str(n) for n in z["names"]], z["shapes"], z["target"],
                               [str(i) for i in z["items"]], self.name)
        manifest = json.loads((self.cache_dir / "manifest.json").read_text())
        self.skipped = list(manifest.get("skipped", []))
        self.scaling = TargetScaling.from_dict(manifest["scaling"])
        fm.target_name = self.scaling.name
        self.sources = {p["item"]: p for p in json.loads((self.cache_dir / "pairs.json").read_text())}
        return fm

    def setup(self, stage: str | None = None) -> None:
        if self.matrix is not None:
            return
        fm = self.load_matrix()
        self.matrix = fm
        names = fm.shape_names
        test = list(self.hparams.test_shapes) if self.hparams.test_shapes else names[-1:]
        val = list(self.hparams.val_shapes) if self.hparams.val_shapes is not None else (
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

    def split(self, name: str) -> FeatureMatrix:
        self.setup()
        return self.splits[name]

    def _loader(self, split: str, shuffle: bool) -> DataLoader:
        ds = PairDataset(self.split(split))
        # batch norm needs >= 2 samples: drop a trailing single-sample batch when training
        drop_last = shuffle and len(ds) % self.batch_size == 1 and len(ds) > self.batch_size
        return DataLoader(ds, batch_size=self.batch_size if shuffle else max(len(ds), 1), shuffle=shuffle,
                          num_workers=self.num_workers, drop_last=drop_last,
                          generator=torch.Generator().manual_seed(int(self.hparams.seed)) if shuffle else None)

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
                            "NOT a human opinion score") if self.source == "synth" else "mean opinion score, scaled to [0,1], higher = more distorted",
            "pairs": len(fm), "features": len(fm.names), "manifest_hash": self.config_hash,
            "skipped_bad_files": len(self.skipped),
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
        from PIL import Image, ImageDraw

        self.setup()
        fm = self.matrix
        idx = np.linspace(0, len(fm) - 1, min(int(n), len(fm))).round().astype(int)
        tile = 128
        canvas = Image.new("RGB", (tile * 2, (tile + 14) * len(idx)), "white")
        draw = ImageDraw.Draw(canvas)
        for r, i in enumerate(idx):
            src = self.sources.get(fm.items[i], {})
            for c, key in enumerate(("reference", "distorted")):
                if src.get(key):
                    canvas.paste(_preview(Path(src[key]), tile), (c * tile, r * (tile + 14) + 14))
            draw.text((2, r * (tile + 14)), f"{fm.items[i]}  {fm.target_name} {fm.target[i]:.2f}", fill="black")
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        canvas.save(path)
        return path


def _preview(mesh_path: Path, size: int):
    """A quick orthographic Lambert preview of a mesh (numpy painter's algorithm, no GL)."""
    from PIL import Image

    m = trimesh.load(mesh_path, force="mesh", process=False)
    v = m.vertices - m.bounds.mean(0)
    v = v / max(np.abs(v).max(), 1e-9) * 0.45 * size
    c, s = math.cos(0.6), math.sin(0.6)
    rot = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]) @ np.array([[1, 0, 0], [0, math.cos(0.4), -math.sin(0.4)], [0, math.sin(0.4), math.cos(0.4)]])
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
