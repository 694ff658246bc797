"""Canonical-form data: pairs (posed depth + mask, canonical depth + mask) seen from the same camera.

Sources:
    synth    procedural humanoids / quadrupeds (``datamodules.synth.figures``); canonical = T-pose
             / standing pose; no download.
    tosca    TOSCA meshes under ``root`` (.mat/.vert+.tri/.off/.ply); canonical = pose 0 (null pose).
    shrec14  SHREC'14 humans under ``root`` with a PSB ``.cla`` (classes = subjects); canonical =
             the pose at ``canonical_pose`` within each class.

Every shape is centred on its bounding-box centre and scaled so that its longest side is 1
(``scale_mode="shape"``, as the thesis) or by the subject's canonical scale
(``scale_mode="subject"``), then rendered with pyrender (EGL) by an orthographic camera on
+z looking down -z (after turning the shape by each azimuth in ``azimuths``). Depth is
normalised to [0, 1]: 0 = background, foreground in [0.1, 1], nearer = larger.

Batches (``B`` samples, ``S = image_size``):
    depth, mask              (B, 1, S, S) float32   posed input; mask in {0, 1}
    canon_depth, canon_mask  (B, 1, S, S) float32   canonical target
    subject (list[str]), subject_idx (B,) int64, pose (B,) int64, view (B,) int64

Cache: ``data_dir/manifest.json`` (generator version + config hash; when complete also one
item per subject file with its sha256 and ``manifest_hash`` over them, so the same seed gives
the same hash) and one ``<subject>.npz`` per subject (depth as float16, masks packed bits),
written atomically; an interrupted ``prepare_data`` resumes with the subjects still missing.

Bad input: every depth image is checked when rendered and when the cache is read (finite,
``image_size`` square, not all background: :func:`depth_image_problem`); a bad one raises
:class:`DataError` naming the file (or subject, pose and view) and the problem. With
``skip_bad=True`` a bad posed image or mesh drops that pose and a bad canonical image drops
the subject, each with a logged warning, counted in ``describe()["skipped_bad_files"]``.

Splits (``split``):
    subject_pose  subjects and poses are each dealt into ``n_folds`` groups (seeded); fold f
                  tests subject group f x pose group f and trains on the other subjects x other
                  poses only (no test subject and no test pose in training). Validation = the
                  items that share exactly one of the two (held out from training, too).
    pose          (TOSCA: one subject per class) every subject's non-canonical poses are dealt
                  into ``n_folds`` groups; fold f tests group f; ``val_per_subject`` training
                  poses per subject go to validation.
"""
from __future__ import annotations

import hashlib
import io
import json
import logging
import zipfile
from collections import Counter
from collections.abc import Sequence
from pathlib import Path

import lightning.pytorch as pl
import numpy as np
import torch
from torch.utils.data import DataLoader, Dataset, WeightedRandomSampler

from datamodules.cache import DataError, stable_hash
from lit3d.retrieval.depthcam import render_depth
from lit3d.utils.io import atomic_write_bytes, file_sha256, write_json

log = logging.getLogger("lit3d")

DATA_VERSION = "canonical-data-1"
SPLITS = ("train", "val", "test")


__all__ = ["CanonicalDataModule", "DataError", "depth_image_problem", "read_subject", "split_pose",
           "split_subject_pose"]


# ----------------------------------------------------------------------------------- geometry
def normalize_mesh(verts: np.ndarray, scale: float | None = None) -> tuple[np.ndarray, float]:
    """Centre on the bounding-box centre, scale so the longest side is 1 (or by ``scale``)."""
    lo, hi = verts.min(0), verts.max(0)
    s = scale if scale is not None else 1.0 / max(float((hi - lo).max()), 1e-12)
    return (verts - (lo + hi) / 2) * s, s


# ----------------------------------------------------------------------------------- depth images
def depth_image_problem(depth: np.ndarray, mask: np.ndarray | None, size: int) -> str | None:
    """What is wrong with one depth image ``(S, S)`` and its mask ``(S, S)``, or None.

    Checked: both ``size`` x ``size``, depth finite, something in view (mask and depth not all
    background)."""
    if depth.shape != (size, size):
        return f"depth image has shape {tuple(depth.shape)}, expected ({size}, {size}) (data.image_size={size})"
    if mask is None or mask.shape != (size, size):
        return f"mask missing or not {size} x {size}"
    if not np.isfinite(depth).all():
        return "depth image contains NaN or inf"
    if not mask.any() or not (depth > 0).any():
        return "depth image is all background (nothing in view)"
    return None


def unpack_mask(packed: np.ndarray | None, size: int) -> np.ndarray | None:
    """``np.packbits`` of an ``(S, S)`` bool mask -> ``(S, S)`` bool; None when absent or of another size."""
    if packed is None or packed.size != (size * size + 7) // 8:
        return None
    return np.unpackbits(packed)[: size * size].reshape(size, size).astype(bool)


def read_subject(path: Path, size: int, n_views: int) -> tuple[dict | None, list[str]]:
    """One subject's cache file -> (``{"depth", "mask", "poses"}`` of its valid images, problems).

    A pose with a bad or missing view is left out of ``poses``; a bad canonical view gives
    ``None`` (the subject cannot be used). Each problem names the file and the image.

    Raises:
        DataError: the file is missing or not a readable ``.npz``.
    """
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise DataError(f"{path}: unreadable cached subject ({type(exc).__name__}: {exc}); "
                        "delete it and run lit3d-data again") from exc
    depth, mask, problems = {}, {}, []
    listed = ["canonical"] + [str(p) for p in arrays.get("poses", [])]
    for key in (f"{p}_{v}" for p in listed for v in range(n_views)):
        if f"depth_{key}" not in arrays:
            problems.append(f"{path}: depth_{key}: depth image missing")
            continue
        d = arrays[f"depth_{key}"].astype(np.float32)
        m = unpack_mask(arrays.get(f"mask_{key}"), size)
        problem = depth_image_problem(d, m, size)
        if problem:
            problems.append(f"{path}: depth_{key}: {problem}")
        else:
            depth[key], mask[key] = d, m.astype(np.float32)
    complete = [p for p in listed if all(f"{p}_{v}" in depth for v in range(n_views))]
    if "canonical" not in complete:
        return None, problems
    return {"depth": depth, "mask": mask, "poses": [int(p) for p in complete[1:]]}, problems


# ----------------------------------------------------------------------------------- sources
class _Source:
    """Enumerates subjects and poses and loads meshes (unnormalised, y up)."""

    kind = "base"

    def subjects(self) -> list[str]: ...
    def poses(self, subject: str) -> list[int]: ...
    def canonical_pose(self, subject: str): ...
    def mesh(self, subject: str, pose) -> tuple[np.ndarray, np.ndarray]: ...
    def category(self, subject: str) -> str:
        return subject


class SynthSource(_Source):
    kind = "synth"

    def __init__(self, kinds: Sequence[str], n_subjects: int, n_poses: int, seed: int, mesh_resolution: int,
                 pose_seed: int, yaw_range: float, pose_strength: float):
        from datamodules.synth import figures

        self.f = figures
        self.kinds = list(kinds)
        self.n_subjects, self.n_poses = n_subjects, n_poses
        self.seed, self.res, self.pose_seed = seed, mesh_resolution, pose_seed
        self.yaw_range, self.strength = yaw_range, pose_strength
        self._subjects = {}
        for i in range(n_subjects):
            kind = self.kinds[i % len(self.kinds)]
            self._subjects[f"{kind}{i:03d}"] = (kind, seed * 1000 + i)

    def subjects(self):
        return list(self._subjects)

    def poses(self, subject):
        return list(range(self.n_poses))

    def canonical_pose(self, subject):
        return "canonical"

    def category(self, subject):
        return self._subjects[subject][0]

    def mesh(self, subject, pose):
        kind, sseed = self._subjects[subject]
        subj = self.f.make_subject(kind, sseed)
        if pose == "canonical":
            return self.f.figure_mesh(subj, None, self.res)
        rng = np.random.default_rng([self.pose_seed, int(pose), 17])
        yaw = float(rng.uniform(-self.yaw_range, self.yaw_range))
        return self.f.figure_mesh(subj, self.f.make_pose(kind, int(pose), self.pose_seed, self.strength),
                                  self.res, yaw_deg=yaw)


class ToscaSource(_Source):
    kind = "tosca"

    def __init__(self, root: str, classes: Sequence[str] | None, canonical_pose: int, up_axis: str):
        from datamodules.readers import tosca

        self.t = tosca
        items = tosca.index_tosca(root, list(classes) if classes else None)
        self.items = {(it.cls, it.pose): it.path for it in items}
        self.canon = canonical_pose
        self.up_axis = up_axis
        missing = sorted({c for c, _ in self.items} - {c for c, p in self.items if p == canonical_pose})
        if missing:
            raise DataError(f"{root}: no canonical pose {canonical_pose} for class(es) {', '.join(missing)}")

    def subjects(self):
        return sorted({c for c, _ in self.items})

    def poses(self, subject):
        return sorted(p for c, p in self.items if c == subject and p != self.canon)

    def canonical_pose(self, subject):
        return self.canon

    def mesh(self, subject, pose):
        v, f = self.t.read_mesh(self.items[(subject, int(pose))])
        return (self.t.z_up_to_y_up(v) if self.up_axis == "z" else v), f


class Shrec14Source(_Source):
    kind = "shrec14"

    def __init__(self, root: str, cla: str | None, canonical_pose: int, up_axis: str):
        from datamodules.readers import shrec14, tosca

        self.t = tosca
        items = shrec14.index_shrec14(root, cla)
        self.items = {(it.subject, it.pose): it.path for it in items}
        self.canon, self.up_axis = canonical_pose, up_axis

    def subjects(self):
        return sorted({s for s, _ in self.items})

    def poses(self, subject):
        return sorted(p for s, p in self.items if s == subject and p != self.canon)

    def canonical_pose(self, subject):
        return self.canon

    def mesh(self, subject, pose):
        v, f = self.t.read_mesh(self.items[(subject, int(pose))])
        return (self.t.z_up_to_y_up(v) if self.up_axis == "z" else v), f


# ----------------------------------------------------------------------------------- splits
def deal(items: Sequence, n_groups: int, seed: int) -> list[list]:
    """Shuffle ``items`` (seeded) and deal them round-robin into ``n_groups`` groups."""
    order = list(items)
    np.random.default_rng(seed).shuffle(order)
    return [sorted(order[g::n_groups], key=str) for g in range(n_groups)]


def split_subject_pose(subjects, poses, n_folds: int, fold: int, seed: int) -> dict[str, list[tuple]]:
    """Strict split: test = S_f x P_f, train = (S \\ S_f) x (P \\ P_f), val = the mixed rest."""
    if n_folds < 2:
        raise DataError("subject_pose split needs n_folds >= 2")
    if len(subjects) < n_folds or len(poses) < n_folds:
        raise DataError(f"subject_pose split with {n_folds} folds needs at least {n_folds} subjects and poses "
                        f"(have {len(subjects)} subjects, {len(poses)} poses)")
    sg = deal(subjects, n_folds, seed)[fold % n_folds]
    pg = deal(poses, n_folds, seed + 1)[fold % n_folds]
    out = {k: [] for k in SPLITS}
    for s in subjects:
        for p in poses:
            a, b = s in sg, p in pg
            out["test" if a and b else "train" if not (a or b) else "val"].append((s, p))
    return out


def split_pose(subject_poses: dict[str, list], n_folds: int, fold: int, seed: int,
               val_per_subject: int = 1) -> dict[str, list[tuple]]:
    """Per subject: poses dealt into folds; fold f -> test, ``val_per_subject`` others -> val."""
    out = {k: [] for k in SPLITS}
    for i, (s, poses) in enumerate(sorted(subject_poses.items())):
        if len(poses) < 2:
            out["train"] += [(s, p) for p in poses]
            continue
        groups = deal(poses, min(n_folds, len(poses)), seed + i)
        test = groups[fold % len(groups)]
        rest = [p for p in poses if p not in test]
        val = rest[:val_per_subject] if len(rest) > val_per_subject else []
        out["test"] += [(s, p) for p in test]
        out["val"] += [(s, p) for p in val]
        out["train"] += [(s, p) for p in rest if p not in val]
    return out


# ----------------------------------------------------------------------------------- dataset
class PairDataset(Dataset):
    """Indexable pairs from the in-memory cache (see module docstring for the item dict)."""

    def __init__(self, records: list[dict], cache: dict[str, dict], subject_index: dict[str, int]):
        self.records, self.cache, self.subject_index = records, cache, subject_index

    def __len__(self):
        return len(self.records)

    def __getitem__(self, i):
        r = self.records[i]
        c = self.cache[r["subject"]]
        pk, ck = f"{r['pose']}_{r['view']}", f"canonical_{r['view']}"
        t = lambda a: torch.from_numpy(np.ascontiguousarray(a, dtype=np.float32))[None]  # noqa: E731
        return {
            "depth": t(c["depth"][pk]), "mask": t(c["mask"][pk]),
            "canon_depth": t(c["depth"][ck]), "canon_mask": t(c["mask"][ck]),
            "subject": r["subject"], "subject_idx": self.subject_index[r["subject"]],
            "pose": int(r["pose"]), "view": int(r["view"]),
        }


def subject_balanced_sampler(records: Sequence[dict], seed: int) -> WeightedRandomSampler:
    """Draws ``len(records)`` items per epoch with replacement, each subject equally often
    (item weight 1 / items of its subject): a subject with many poses (TOSCA's michael has 20,
    wolf 3) no longer dominates the canonical shape the network learns."""
    counts: dict[str, int] = {}
    for r in records:
        counts[r["subject"]] = counts.get(r["subject"], 0) + 1
    weights = torch.tensor([1.0 / counts[r["subject"]] for r in records], dtype=torch.double)
    return WeightedRandomSampler(weights, num_samples=len(records), replacement=True,
                                 generator=torch.Generator().manual_seed(int(seed)))


class CanonicalDataModule(pl.LightningDataModule):
    """Posed/canonical depth pairs (synthetic figures, TOSCA or SHREC'14); see module docstring."""

    def __init__(
        self,
        data_dir: str,
        source: str = "synth",
        root: str | None = None,
        image_size: int = 128,
        seed: int = 42,
        batch_size: int = 8,
        num_workers: int = 0,
        # synthetic figures
        kinds: Sequence[str] = ("humanoid", "quadruped"),
        n_subjects: int = 12,
        n_poses: int = 12,
        mesh_resolution: int = 56,
        pose_seed: int = 0,
        yaw_range: float = 15.0,
        pose_strength: float = 1.0,
        # real data
        classes: Sequence[str] | None = None,
        canonical_pose: int = 0,
        up_axis: str = "z",
        cla: str | None = None,
        # rendering
        azimuths: Sequence[float] = (0.0,),
        scale_mode: str = "shape",
        # splits
        split: str = "subject_pose",
        n_folds: int = 3,
        fold: int = 0,
        val_per_subject: int = 1,
        max_val_items: int | None = 64,
        skip_bad: bool = False,
        balance_subjects: bool = False,
    ):
        super().__init__()
        self.save_hyperparameters()
        if source not in ("synth", "tosca", "shrec14"):
            raise DataError(f"unknown canonical data source '{source}' (synth, tosca, shrec14)")
        if source != "synth" and not root:
            raise DataError(f"data source '{source}' needs root=<folder with the meshes>")
        if scale_mode not in ("shape", "subject"):
            raise DataError(f"scale_mode must be 'shape' or 'subject', got '{scale_mode}'")
        if split not in ("subject_pose", "pose"):
            raise DataError(f"split must be 'subject_pose' or 'pose', got '{split}'")
        self.data_dir = Path(data_dir)
        self._source = None
        self.cache: dict[str, dict] = {}
        self.splits: dict[str, list[dict]] = {}
        self.datasets: dict[str, PairDataset] = {}
        self.subject_index: dict[str, int] = {}
        self.skipped: list[str] = []  # bad inputs skipped (skip_bad=True), rendering + loading

    # ------------------------------------------------------------------ configuration
    @property
    def source(self) -> _Source:
        if self._source is None:
            hp = self.hparams
            if hp.source == "synth":
                self._source = SynthSource(hp.kinds, hp.n_subjects, hp.n_poses, hp.seed, hp.mesh_resolution,
                                           hp.pose_seed, hp.yaw_range, hp.pose_strength)
            elif hp.source == "tosca":
                self._source = ToscaSource(hp.root, hp.classes, hp.canonical_pose, hp.up_axis)
            else:
                self._source = Shrec14Source(hp.root, hp.cla, hp.canonical_pose, hp.up_axis)
        return self._source

    def config_hash(self) -> str:
        """Hash of everything that changes the cached images (not splits or loader settings)."""
        hp = self.hparams
        keys = ["source", "image_size", "azimuths", "scale_mode"]
        if hp.source == "synth":
            keys += ["kinds", "n_subjects", "n_poses", "mesh_resolution", "pose_seed", "yaw_range", "pose_strength",
                     "seed"]
        else:
            keys += ["root", "classes", "canonical_pose", "up_axis", "cla"]
        cfg = {k: (list(hp[k]) if isinstance(hp[k], (list, tuple)) else hp[k]) for k in keys}
        cfg["version"] = DATA_VERSION
        if hp.skip_bad:  # a cache rendered while skipping may lack poses; only added when set (old hashes hold)
            cfg["skip_bad"] = True
        return hashlib.sha256(json.dumps(cfg, sort_keys=True, default=str).encode()).hexdigest()[:16]

    @property
    def manifest_path(self) -> Path:
        return self.data_dir / "manifest.json"

    def _manifest(self) -> dict | None:
        try:
            return json.loads(self.manifest_path.read_text())
        except (OSError, ValueError):
            return None

    # ------------------------------------------------------------------ generation
    def normalized_mesh(self, subject: str, pose) -> tuple[np.ndarray, np.ndarray]:
        """The mesh of (subject, pose) centred and scaled as it is rendered (``pose="canonical"`` ok)."""
        src = self.source
        key = src.canonical_pose(subject) if pose == "canonical" else pose
        v, f = src.mesh(subject, key)
        scale = None
        if self.hparams.scale_mode == "subject":
            cv, _ = src.mesh(subject, src.canonical_pose(subject))
            _, scale = normalize_mesh(cv)
        v, _ = normalize_mesh(v, scale)
        return v, f

    def _render_pose(self, subject: str, pose) -> dict[str, np.ndarray]:
        """Depth (float16) and packed mask of every view of one pose; DataError for a bad image."""
        hp = self.hparams
        v, f = self.normalized_mesh(subject, pose)
        out = {}
        for vi, az in enumerate(hp.azimuths):
            d, m = render_depth(v, f, hp.image_size, az)
            problem = depth_image_problem(d, m, hp.image_size)
            if problem:
                raise DataError(f"view {vi}: rendered {problem} (mesh outside the view?)")
            out[f"depth_{pose}_{vi}"] = d.astype(np.float16)
            out[f"mask_{pose}_{vi}"] = np.packbits(m)
        return out

    def _render_subject(self, subject: str) -> dict[str, np.ndarray]:
        """Arrays of one subject's cache file; ``skipped`` lists the poses dropped by ``skip_bad``."""
        arrays: dict[str, np.ndarray] = {}
        poses, skipped = ["canonical"] + list(self.source.poses(subject)), []
        for p in poses:
            try:
                arrays.update(self._render_pose(subject, p))
            except Exception as exc:
                msg = f"{subject} pose {p}: {exc}"
                if not self.hparams.skip_bad or p == "canonical":
                    raise DataError(msg) from exc
                log.warning("skipping: %s", msg)
                skipped.append(msg)
        kept = [p for p in poses[1:] if f"depth_{p}_0" in arrays]
        arrays["poses"] = np.array([str(p) for p in kept])
        arrays["skipped"] = np.array(skipped, dtype=str)
        return arrays

    def _manifest_items(self, subjects: Sequence[str]) -> tuple[list[dict], list[str]]:
        """One item per subject file (with its sha256) and the problems skipped while rendering."""
        items, skipped = [], []
        for s in subjects:
            path = self.data_dir / f"{s}.npz"
            items.append({"file": path.name, "subject": s, "sha256": file_sha256(path)})
            with np.load(path, allow_pickle=False) as z:
                skipped += [str(m) for m in z["skipped"]] if "skipped" in z.files else []
        return items, skipped

    def prepare_data(self) -> None:
        """Render every subject once into ``data_dir`` (resumable, atomic); no-op when cached."""
        h = self.config_hash()
        man = self._manifest()
        if man and man.get("config_hash") == h and man.get("complete"):
            return
        self.data_dir.mkdir(parents=True, exist_ok=True)
        subjects = self.source.subjects()
        if man is None or man.get("config_hash") != h:
            for old in self.data_dir.glob("*.npz"):
                old.unlink()
        base = {"generator_version": DATA_VERSION, "config_hash": h, "source": self.hparams.source,
                "image_size": self.hparams.image_size, "subjects": subjects,
                "categories": {s: self.source.category(s) for s in subjects}}
        write_json(self.manifest_path, {**base, "complete": False})
        try:
            from tqdm import tqdm

            it = tqdm(subjects, desc="render canonical pairs", leave=False)
        except ImportError:  # pragma: no cover
            it = subjects
        for s in it:
            path = self.data_dir / f"{s}.npz"
            if path.is_file():
                continue
            arrays = self._render_subject(s)
            buf = io.BytesIO()
            np.savez_compressed(buf, **arrays)
            atomic_write_bytes(path, buf.getvalue())
        items, skipped = self._manifest_items(subjects)
        write_json(self.manifest_path, {**base, "complete": True, "items": items,
                                        "manifest_hash": stable_hash(items), "skipped": skipped})

    # ------------------------------------------------------------------ loading and splits
    def _load_cache(self) -> None:
        man = self._manifest()
        if not man or not man.get("complete") or man.get("config_hash") != self.config_hash():
            raise DataError(f"{self.data_dir}: no complete cache for this config; run prepare_data() (lit3d-data)")
        hp = self.hparams
        self.manifest = man
        self.skipped = list(man.get("skipped", []))
        for s in man["subjects"]:
            entry, problems = read_subject(self.data_dir / f"{s}.npz", hp.image_size, len(hp.azimuths))
            if problems and not hp.skip_bad:
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
        hp = self.hparams
        subject_poses = {s: c["poses"] for s, c in self.cache.items()}
        if hp.split == "subject_pose":
            all_poses = sorted({p for ps in subject_poses.values() for p in ps})
            pairs = split_subject_pose(list(subject_poses), all_poses, hp.n_folds, hp.fold, hp.seed)
            pairs = {k: [(s, p) for s, p in v if p in subject_poses[s]] for k, v in pairs.items()}
        else:
            pairs = split_pose(subject_poses, hp.n_folds, hp.fold, hp.seed, hp.val_per_subject)
        if hp.max_val_items and len(pairs["val"]) > hp.max_val_items:
            idx = np.random.default_rng(hp.seed).choice(len(pairs["val"]), hp.max_val_items, replace=False)
            pairs["val"] = [pairs["val"][i] for i in sorted(idx)]
        views = range(len(hp.azimuths))
        self.splits = {k: [{"subject": s, "pose": p, "view": v} for s, p in v_ for v in views]
                       for k, v_ in pairs.items()}
        for k in SPLITS:
            if not self.splits[k]:
                raise DataError(f"split '{k}' is empty (subjects {len(subject_poses)}, folds {hp.n_folds}): "
                                "use more subjects/poses or fewer folds")
            self.datasets[k] = PairDataset(self.splits[k], self.cache, self.subject_index)
        tr = {(r["subject"], r["pose"]) for r in self.splits["train"]}
        te = self.splits["test"]
        if hp.split == "subject_pose":
            assert not ({r["subject"] for r in te} & {s for s, _ in tr}), "test subject leaked into training"
            assert not ({r["pose"] for r in te} & {p for _, p in tr}), "test pose leaked into training"
        assert not ({(r["subject"], r["pose"]) for r in te} & tr), "test item leaked into training"

    def _loader(self, split: str, shuffle: bool) -> DataLoader:
        return DataLoader(self.datasets[split], batch_size=self.hparams.batch_size, shuffle=shuffle,
                          num_workers=self.hparams.num_workers, persistent_workers=self.hparams.num_workers > 0)

    def train_dataloader(self):
        if not self.hparams.balance_subjects:
            return self._loader("train", True)
        return DataLoader(self.datasets["train"], batch_size=self.hparams.batch_size,
                          sampler=subject_balanced_sampler(self.datasets["train"].records, self.hparams.seed),
                          num_workers=self.hparams.num_workers, persistent_workers=self.hparams.num_workers > 0)

    def val_dataloader(self):
        return self._loader("val", False)

    def test_dataloader(self):
        return self._loader("test", False)

    # ------------------------------------------------------------------ inspection
    def describe(self) -> dict:
        if not self.datasets:
            self.setup()
        cats = self.manifest.get("categories", {})
        out = {"source": self.hparams.source, "image_size": self.hparams.image_size,
               "manifest_hash": self.manifest.get("manifest_hash", self.manifest["config_hash"]),
               "config_hash": self.manifest["config_hash"], "generator_version": self.manifest["generator_version"],
               "skipped_bad_files": len(self.skipped),
               "split_mode": self.hparams.split, "fold": self.hparams.fold, "n_folds": self.hparams.n_folds,
               "subjects": len(self.cache)}
        for k in SPLITS:
            recs = self.splits[k]
            out[k] = {"items": len(recs), "subjects": len({r["subject"] for r in recs}),
                      "poses": len({r["pose"] for r in recs}),
                      "per_category": dict(Counter(cats.get(r["subject"], r["subject"]) for r in recs))}
        return out

    def show(self, n: int, path: str | Path, split: str = "test") -> Path:
        """PNG with one row per sample: posed depth | posed mask | canonical depth | canonical mask."""
        from PIL import Image

        if not self.datasets:
            self.setup()
        ds = self.datasets[split]
        rows = []
        for i in np.linspace(0, len(ds) - 1, min(n, len(ds))).astype(int):
            b = ds[int(i)]
            rows.append(np.concatenate([b[k][0].numpy() for k in ("depth", "mask", "canon_depth", "canon_mask")], 1))
        img = (np.concatenate(rows, 0) * 255).clip(0, 255).astype(np.uint8)
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        buf = io.BytesIO()
        Image.fromarray(img).save(buf, format="PNG")
        atomic_write_bytes(path, buf.getvalue())
        return path
