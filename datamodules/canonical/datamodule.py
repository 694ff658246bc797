"""Canonical-form data: pairs (posed depth + mask, canonical depth + mask) seen from the same camera.

Settings (:mod:`datamodules.canonical.settings`, one frozen dataclass per config node):
``data.source`` (``kind``: ``synth`` procedural figures, ``anny``, or meshes under ``data.root``: ``tosca``,
``shrec14``, ``faust``, ``sumner``; only that source's fields), ``data.render``, ``data.split``,
``data.training``; flat: ``data_dir``, ``image_size``, ``root``, ``seed``, ``batch_size``, ``num_workers``,
``prepare_workers``, ``skip_bad``.

Every shape is centred on its bounding-box centre and scaled so that its longest side is 1
(``render.scale_mode="shape"``, as the thesis) or by the subject's canonical scale
(``"subject"``), then rendered with pyrender (EGL) by an orthographic camera on
+z looking down -z (after turning the shape by each azimuth in ``render.azimuths``). Depth is
normalised to [0, 1]: 0 = background, foreground in [0.1, 1], nearer = larger.
``render.view_mode`` (:mod:`lit3d.geometry.broadside`): ``fixed`` = the azimuths as given; ``broadside`` = each
shape (posed and canonical alike) first turned so that its broad side faces the camera, then
by each azimuth. ``training.flip_lr``: training inputs mirrored left-right with probability 1/2; the target
with them under ``fixed`` only (:class:`~datamodules.canonical.dataset.CanonicalPairDataset` says why).
``split.eval_views``: indices into ``render.azimuths`` that val, test and the pooled held-out set use (null:
all); training always sees every view, so extra azimuths are training augmentation while evaluation keeps
one view per pose. ``training.roll_deg``: training inputs turned in the image plane by up to that many
degrees (a rolled camera; the target stays). ``training.blend_poses``: extra training poses per subject,
vertex blends of two of the fold's training poses (:mod:`datamodules.canonical.blends`);
``source.own_poses`` (synth): each subject's own training-only poses; ``split.val_poses=own`` validates in
the validation subjects' own poses (new poses, as the test), not the training ones.
``split.train_pose_fraction``: train on that share of each subject's training poses (a learning curve).
``render.flow_targets``: also cache, for every pose whose mesh corresponds to the canonical one, the warp
head's backward flow and visibility (:mod:`datamodules.canonical.flow`); items carry them. Options measured
and not adopted were removed (:mod:`datamodules.canonical.parked`).

Batches (``B`` samples, ``S = image_size``):
    depth, mask              (B, 1, S, S) float32   posed input; mask in {0, 1}
    canon_depth, canon_mask  (B, 1, S, S) float32   canonical target
    subject (list[str]), subject_idx (B,) int64, pose (B,) int64, view (B,) int64
    flow (B, 2, S, S), vis (B, 1, S, S) float32, has_flow (B,) bool   (``flow_targets``; zeros and False
                             for items without targets; backward: at canonical pixels)

Cache (:class:`datamodules.cache.CacheBuilder`, the one cache scheme of every DataModule):
``data_dir/subjects/<subject>.npz`` per subject (depth as float16, masks packed bits; layout in
:mod:`datamodules.canonical.images`), written atomically; ``prepare.json`` marks a preparation
under way, ``manifest.json`` (config, config hash, one item per subject file with its sha256,
``manifest_hash`` over them, so the same seed gives the same hash; plus ``complete``,
``subjects``, ``categories``, ``skipped``) is written last. An interrupted ``prepare_data``
resumes with the subjects still missing. ``prepare_workers`` = N renders the subjects in N processes
(:mod:`datamodules.canonical.prepare`; the same files as one process).

Bad input: every depth image is checked when rendered and when the cache is read (finite,
``image_size`` square, not all background: :func:`depth_image_problem`); a bad one raises
:class:`DataError` naming the file (or subject, pose and view) and the problem. With
``skip_bad=True`` a bad posed image or mesh drops that pose and a bad canonical image drops
the subject, each with a logged warning, counted in ``describe()["skipped_bad_files"]``.

Splits (``split.mode``: ``subject_pose``, ``pose`` or ``all``): :mod:`datamodules.canonical.splits`.
"""
from __future__ import annotations

import logging
from pathlib import Path

import lightning.pytorch as pl
import numpy as np
from torch.utils.data import DataLoader

from datamodules.cache import CacheBuilder, DataError
from datamodules.canonical.blends import add_blends
from datamodules.canonical.dataset import CanonicalPairDataset, mirror_views, subject_balanced_sampler
from datamodules.canonical.images import (depth_image_problem, depth_pairs_png, read_subject, remove_legacy_subject_files,
                                          unpack_mask)
from datamodules.canonical.flat_config import upgrade_data_config
from datamodules.canonical.prepare import SUBJECTS_DIR, RenderJob, subject_file, write_subject_files
from datamodules.canonical.rendering import PairRenderer
from datamodules.canonical.sheets import pose_sheet
from datamodules.canonical.settings import (ROOTLESS, RenderSettings, SourceSettings, SplitSettings, TrainingSettings,
                                            parse, parse_source)
from datamodules.canonical.sources import Shrec14Source, SynthSource, ToscaSource, build_source
from datamodules.canonical.splits import (CANONICAL_SPLITS, deal, fold_pairs, split_counts, split_pose, split_subject_pose,
                                          thin_training)
from datamodules.loaders import evaluation_loader
from lit3d.body_model import bodies
from lit3d.utils.extras import require

log = logging.getLogger("lit3d")

GENERATOR = "canonical"
DATA_VERSION = "canonical-data-1"
FLOW_VERSION = "flow-1"  # bump when datamodules.canonical.flow changes what it writes (either direction)

__all__ = ["CANONICAL_SPLITS", "CanonicalDataModule", "DataError", "CanonicalPairDataset", "Shrec14Source", "SynthSource",
           "ToscaSource", "deal", "depth_image_problem", "read_subject", "split_pose", "split_subject_pose",
           "subject_balanced_sampler", "unpack_mask"]


class CanonicalDataModule(pl.LightningDataModule):
    """Posed/canonical depth pairs (synthetic figures, TOSCA or SHREC'14); see module docstring."""

    def __init__(self, data_dir: str, image_size: int, source: dict | SourceSettings | None = None,
                 root: str | None = None, render: dict | RenderSettings | None = None,
                 split: dict | SplitSettings | None = None, training: dict | TrainingSettings | None = None,
                 seed: int = 42, batch_size: int = 8, num_workers: int = 0, prepare_workers: int = 0,
                 skip_bad: bool = False):
        """``source``, ``render``, ``split``, ``training``: the config nodes of
        :mod:`datamodules.canonical.settings` (None: every default; ``source``: synthetic figures)."""
        super().__init__()
        self.save_hyperparameters()
        self.source_settings = parse_source(source if source is not None else {"kind": "synth"})
        self.render = parse(RenderSettings, render, "render")
        self.split = parse(SplitSettings, split, "split")
        self.training = parse(TrainingSettings, training, "training")
        if self.source_settings.kind not in ROOTLESS and not root:
            raise DataError(f"data source '{self.source_settings.kind}' needs root=<folder with the meshes>")
        if self.source_settings.kind == "anny":  # the Anny body model: the extra lit3d[body]
            require("body", "data.source.kind=anny")
        n_views = len(self.render.azimuths)
        eval_views = self.split.eval_views
        if eval_views is not None and (not eval_views or any(not 0 <= int(v) < n_views for v in eval_views)):
            raise DataError(f"eval_views must be indices into azimuths (0..{n_views - 1}), got {list(eval_views)}")
        self.data_dir = Path(data_dir)
        self.root, self.image_size, self.seed = root, int(image_size), int(seed)
        self.batch_size, self.num_workers, self.prepare_workers = int(batch_size), int(num_workers), int(prepare_workers)
        self.skip_bad = bool(skip_bad)
        self._source = None
        self.manifest: dict = {}
        self.cache: dict[str, dict] = {}
        self.splits: dict[str, list[dict]] = {}
        self.datasets: dict[str, CanonicalPairDataset] = {}
        self.subject_index: dict[str, int] = {}
        self.skipped: list[str] = []  # bad inputs skipped (skip_bad=True), rendering + loading

    @classmethod
    def from_flat(cls, data_dir: str, image_size: int, **flat) -> "CanonicalDataModule":
        """Built from the flat keys of a data config written before the settings were nodes
        (:func:`~datamodules.canonical.flat_config.upgrade_data_config`)."""
        return cls(**upgrade_data_config({"data_dir": data_dir, "image_size": image_size, **flat}))

    # ------------------------------------------------------------------ configuration
    @property
    def source(self):
        """The mesh source (:mod:`datamodules.canonical.sources`), built on first use."""
        if self._source is None:
            self._source = build_source(self.source_settings, self.root)
        return self._source

    @property
    def source_kind(self) -> str:
        """The data source's name (``data.source.kind``: synth, anny, tosca, ...)."""
        return self.source_settings.kind

    def cache_config(self) -> dict:
        """Everything that changes the cached images (not splits or loader settings), under the keys the
        caches have always hashed (the same cache keeps its hash)."""
        src, render = self.source_settings, self.render
        cfg = {"source": src.kind, "image_size": self.image_size, "azimuths": list(render.azimuths),
               "scale_mode": render.scale_mode, **src.cache_fields(self.root)}
        if src.kind == "anny":  # the sampler's and anny's versions: another release may pose differently
            cfg["bodies"] = [bodies.BODIES_VERSION, bodies.anny_version()]
        if self.skip_bad:  # a cache rendered while skipping may lack poses
            cfg["skip_bad"] = True
        if render.view_mode != "fixed":  # absent for the old convention: its caches keep their hash
            cfg["view_mode"] = render.view_mode
        if render.flow_targets:  # absent without flows: those caches keep their hash
            cfg["flow_targets"] = FLOW_VERSION
        return cfg

    def cache_builder(self) -> CacheBuilder:
        """The cache of ``data_dir`` for this config (see the module docstring)."""
        return CacheBuilder(self.data_dir, GENERATOR, DATA_VERSION, self.cache_config(), items_dir=SUBJECTS_DIR)

    def config_hash(self) -> str:
        """Hash of :meth:`cache_config` with the generator and its version (the manifest's ``config_hash``)."""
        return self.cache_builder().config_hash

    # ------------------------------------------------------------------ generation
    @property
    def renderer(self) -> PairRenderer:
        """Renders subjects (:class:`~datamodules.canonical.rendering.PairRenderer`)."""
        return PairRenderer(self.source, self.render, self.image_size, self.skip_bad)

    def normalized_mesh(self, subject: str, pose) -> tuple[np.ndarray, np.ndarray]:
        """The mesh of (subject, pose) centred and scaled as it is rendered (``pose="canonical"`` ok)."""
        return self.renderer.normalized_mesh(subject, pose)

    def canonical_turned(self, subject: str, view: int, turn_deg: float) -> tuple[np.ndarray, np.ndarray]:
        """Canonical depth and mask ``(S, S)`` of ``subject`` from view ``view`` turned by ``turn_deg``
        (the jittered ceiling row of the evaluation, :func:`lit3d.canonical.evaluator.jittered_target`)."""
        return self.renderer.canonical_turned(subject, view, turn_deg)

    def _render_subject(self, subject: str) -> dict[str, np.ndarray]:
        """Arrays of one subject's cache file (:meth:`PairRenderer.render_subject`)."""
        return self.renderer.render_subject(subject)

    def prepare_data(self) -> None:
        """Render every subject once into ``data_dir`` (resumable, atomic); no-op when cached."""
        self.cache_builder().prepare_once(self._render_subjects,
                                          before=lambda: remove_legacy_subject_files(self.data_dir))

    def _render_subjects(self, builder: CacheBuilder) -> tuple[list[dict], dict]:
        """Render the subjects still missing from ``builder`` (``prepare_workers`` processes); (items, manifest extra)."""
        subjects = self.source.subjects()
        builder.total_items = len(subjects)  # named by a Ctrl-C's stop line (each builder.has() is a stop point)
        job = RenderJob(self.source_settings, self.root, self.render, self.image_size, self.skip_bad)
        skipped = write_subject_files(builder, subjects, self._render_subject, job, self.prepare_workers)
        return [{"file": subject_file(s), "subject": s} for s in subjects], {
            "complete": True, "source": self.source_kind, "image_size": self.image_size,
            "subjects": subjects, "categories": {s: self.source.category(s) for s in subjects}, "skipped": skipped}

    # ------------------------------------------------------------------ loading and splits
    def _load_cache(self) -> None:
        builder = self.cache_builder()
        man = builder.manifest()
        if not man or not man.get("complete") or man.get("config_hash") != builder.config_hash:
            raise DataError(f"{self.data_dir}: no complete cache for this config; run prepare_data() (lit3d-data)")
        self.manifest = man
        self.skipped = list(man.get("skipped", []))
        for item in man["items"]:
            s = item["subject"]
            entry, problems = read_subject(builder.path(item["file"]), self.image_size, len(self.render.azimuths))
            if problems and not self.skip_bad:
                raise DataError(problems[0])
            for msg in problems:
                log.warning("skipping: %s", msg)
            self.skipped += problems
            if entry is not None:
                self.cache[s] = entry
        if not self.cache:
            raise DataError(f"{self.data_dir}: no usable subject left ({len(self.skipped)} bad images skipped)")
        self.subject_index = {s: i for i, s in enumerate(man["subjects"])}

    def setup(self, stage: str | None = None) -> None:
        if self.datasets:
            return
        self._load_cache()
        sp, tr = self.split, self.training
        subject_poses = {s: c["poses"] for s, c in self.cache.items()}
        pairs = self._pairs(sp.fold)
        pairs["train"] = thin_training(pairs["train"], sp.train_pose_fraction, self.seed + sp.fold)
        if sp.max_val_items and len(pairs["val"]) > sp.max_val_items:
            idx = np.random.default_rng(self.split_seed).choice(len(pairs["val"]), sp.max_val_items, replace=False)
            pairs["val"] = [pairs["val"][i] for i in sorted(idx)]
        self.splits = {k: [{"subject": s, "pose": p, "view": v} for s, p in v_ for v in self.views(k)]
                       for k, v_ in pairs.items()}
        if tr.blend_poses:  # rendered now: they depend on the fold's training poses
            added = add_blends(self.cache, pairs["train"], tr.blend_poses, self.seed, sp.fold, self.renderer.raw_mesh,
                               self.renderer.render_views)
            self.splits["train"] += [{"subject": s, "pose": p, "view": v} for s, p in added for v in self.views("train")]
        for k in CANONICAL_SPLITS:
            if not self.splits[k] and sp.mode == "all" and k != "test":
                continue  # evaluation only: nothing to train or validate on
            if not self.splits[k]:
                raise DataError(f"split '{k}' is empty (subjects {len(subject_poses)}, folds {sp.n_folds}): "
                                "use more subjects/poses or fewer folds")
            self.datasets[k] = CanonicalPairDataset(self.splits[k], self.cache, self.subject_index,
                                           flip_lr=tr.flip_lr and k == "train", flip_target=self.render.view_mode == "fixed",
                                           mirror_view=mirror_views(self.render.azimuths),
                                           roll_deg=tr.roll_deg if k == "train" else 0.0)
        tr = {(r["subject"], r["pose"]) for r in self.splits["train"]}
        te = self.splits["test"]
        leaks = []
        if sp.mode == "subject_pose":
            leaks += ["test subject in training"] * bool({r["subject"] for r in te} & {s for s, _ in tr})
            leaks += ["test pose in training"] * bool({r["pose"] for r in te} & {p for _, p in tr})
            if sp.val_subjects is not None:
                va = {r["subject"] for r in self.splits["val"]}
                leaks += ["validation subject in test or training"] * bool(va & ({r["subject"] for r in te} |
                                                                                {s for s, _ in tr}))
        leaks += ["test item in training"] * bool({(r["subject"], r["pose"]) for r in te} & tr)
        if leaks:  # a raise, not an assert: it must hold under python -O too
            raise DataError(f"{self.data_dir}: split leak: {', '.join(leaks)}")

    @property
    def split_seed(self) -> int:
        """The seed that deals subjects and poses into folds (``split_seed``, else ``seed``)."""
        return int(self.seed if self.split.seed is None else self.split.seed)

    def _pairs(self, fold: int) -> dict[str, list[tuple]]:
        """``{split: [(subject, pose), ...]}`` of fold ``fold`` over the loaded cache."""
        sp = self.split
        return fold_pairs({s: c["poses"] for s, c in self.cache.items()}, sp.mode, sp.n_folds, fold,
                          self.split_seed, sp.val_per_subject, sp.val_subjects, sp.val_poses)

    def held_out_records(self) -> list[dict]:
        """Every item some fold tests (``{"subject", "pose", "view"}``, sorted): the set that the
        pooled protocol (:mod:`lit3d.canonical.pooled`) scores, each from the fold that held it out.
        For ``split=pose`` that is every non-canonical pose of every subject with 2+ poses."""
        if not self.cache:
            self.setup()
        pairs = sorted({sp for f in range(self.split.n_folds) for sp in self._pairs(f)["test"]}, key=str)
        return [{"subject": s, "pose": p, "view": v} for s, p in pairs for v in self.views("test")]

    def views(self, split: str) -> list[int]:
        """Indices into ``azimuths`` that ``split`` uses: training every view, val/test (and the pooled
        held-out set) ``eval_views`` when set (more training views than evaluation asks for)."""
        every = list(range(len(self.render.azimuths)))
        if split == "train" or self.split.eval_views is None:
            return every
        return [int(v) for v in self.split.eval_views]

    def held_out_ids(self) -> list[str]:
        """``"subject/pose/view"`` of :meth:`held_out_records`."""
        return [f"{r['subject']}/{int(r['pose'])}/{r['view']}" for r in self.held_out_records()]

    @property
    def _workers(self) -> dict:
        """The loaders' worker settings (``num_workers``, kept alive between epochs when there are any)."""
        return dict(num_workers=self.num_workers, persistent_workers=self.num_workers > 0)

    def _loader(self, split: str, shuffle: bool) -> DataLoader:
        if not shuffle:  # val/test: every item once, also under DDP
            return evaluation_loader(self.datasets[split], self.batch_size, **self._workers)
        return DataLoader(self.datasets[split], batch_size=self.batch_size, shuffle=shuffle, **self._workers)

    def train_dataloader(self):
        train = self.datasets["train"]
        if self.training.balance_subjects:
            return DataLoader(train, batch_size=self.batch_size, sampler=subject_balanced_sampler(train.records, self.seed),
                              **self._workers)
        return self._loader("train", True)

    def val_dataloader(self):
        return self._loader("val", False)

    def test_dataloader(self):
        return self._loader("test", False)

    # ------------------------------------------------------------------ inspection
    def describe(self) -> dict:
        if not self.datasets:
            self.setup()
        cats = self.manifest.get("categories", {})
        out = {"source": self.source_kind, "image_size": self.image_size,
               "manifest_hash": self.manifest.get("manifest_hash", self.manifest["config_hash"]),
               "config_hash": self.manifest["config_hash"], "generator_version": self.manifest["version"],
               "skipped_bad_files": len(self.skipped),
               "split_mode": self.split.mode, "fold": self.split.fold, "n_folds": self.split.n_folds,
               "subjects": len(self.cache)}
        out.update({k: split_counts(self.splits[k], cats) for k in CANONICAL_SPLITS})
        return out

    def show(self, n: int, path: str | Path, split: str = "test") -> Path:
        """PNG with one row per sample: posed depth | posed mask | canonical depth | canonical mask; beside
        it ``<stem>_shaded.png`` (:func:`~datamodules.canonical.sheets.pose_sheet`: shaded subjects)."""
        if not self.datasets:
            self.setup()
        path = Path(path)
        shaded = pose_sheet(self, path.with_name(path.stem + "_shaded.png"), n_subjects=max(1, min(n, 6)))
        log.info("wrote %s", shaded)
        return depth_pairs_png(self.datasets[split], n, path)
