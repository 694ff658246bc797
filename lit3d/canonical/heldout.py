"""Held-out test items of one cross-validation fold, saved for the pooled protocol
(:mod:`lit3d.canonical.pooled`).

After the test, :func:`lit3d.canonical.evaluator.protocol` writes ``heldout.npz`` into the run dir
(rank 0) with, for the ``N`` test items in dataset order (``S = image_size``):

    pred_depth, pred_mask, depth, mask   (N, S, S) float16   prediction (mask probability), posed input
    canon_depth, canon_mask              (N, S, S) float16   true canonical form
    subject (N,) str, pose (N,) int64, view (N,) int64, item (N,) str "subject/pose/view"
    expected (M,) str       every item of the data (all folds): what the pooled set must cover once
    source () str           "model" or "unet" (the prediction row's name, by task.arch)
    fold, n_folds () int64; data () str: the data config as JSON (to rebuild meshes for the mesh rows)
    settings () str         the retrieval settings as JSON (the run's evaluation settings, the task's mask_threshold)

:func:`pool` merges the files of every fold and checks that each expected item appears exactly once.
"""
from __future__ import annotations

import io
import json
from collections import Counter
from pathlib import Path

import numpy as np

from datamodules.canonical.flat_config import full_data_config
from lit3d.utils.io import atomic_write_bytes

HELDOUT_FILE = "heldout.npz"
IMAGES = ("pred_depth", "pred_mask", "depth", "mask", "canon_depth", "canon_mask")
# the settings the pooled protocol scores with (saved as ``settings`` in heldout.npz): the task's
# mask_threshold and the run's evaluation settings (the config's ``evaluation`` node)
SETTINGS = ("retrieval", "mask_threshold", "prediction_smooth_px", "chance_trials", "mesh_baselines",
            "baseline_max_vertices", "baseline_landmarks", "baseline_smacof_eps")


def settings_of(cfg: dict) -> dict:
    """The retrieval settings (:data:`SETTINGS`) present in ``cfg`` (the evaluation settings with the
    task's ``mask_threshold``)."""
    return {k: cfg[k] for k in SETTINGS if k in cfg}


def item_ids(subjects, poses, views) -> np.ndarray:
    """``(N,)`` str ids ``"subject/pose/view"``."""
    return np.array([f"{s}/{int(p)}/{int(v)}" for s, p, v in zip(subjects, poses, views)])


def heldout_arrays(outputs: dict, subject_names: dict[int, str], expected, source: str, data: dict,
                   fold: int, n_folds: int, settings: dict | None = None) -> dict[str, np.ndarray]:
    """The arrays of ``heldout.npz`` from the task's gathered test outputs (CPU tensors, dataset
    order, fields of :data:`lit3d.canonical.module.TEST_OUTPUTS`); ``expected``: every item id of
    the data (:meth:`datamodules.canonical.CanonicalDataModule.all_item_ids`)."""
    subjects = np.array([subject_names[int(i)] for i in outputs["subject_idx"]])
    pose, view = outputs["pose"].numpy().astype(np.int64), outputs["view"].numpy().astype(np.int64)
    out = {k: outputs[k][:, 0].numpy().astype(np.float16) for k in IMAGES}
    out.update(subject=subjects, pose=pose, view=view, item=item_ids(subjects, pose, view),
               expected=np.array(sorted(expected)), source=np.array(source), fold=np.array(int(fold)),
               n_folds=np.array(int(n_folds)), data=np.array(json.dumps(data, sort_keys=True, default=list)),
               settings=np.array(json.dumps(settings or {}, sort_keys=True, default=list)))
    return out


def save_heldout(path: str | Path, arrays: dict[str, np.ndarray]) -> Path:
    """Write ``heldout.npz`` atomically."""
    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays)
    return atomic_write_bytes(Path(path), buf.getvalue())


def load_heldout(path: str | Path) -> dict[str, np.ndarray]:
    """One fold's arrays (a run dir or the file itself)."""
    path = Path(path)
    path = path / HELDOUT_FILE if path.is_dir() else path
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no held-out items (run lit3d-train/lit3d-eval of the canonical task "
                                "with retrieval on; it writes heldout.npz after the test)")
    with np.load(path, allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


def coverage_problems(items, expected) -> list[str]:
    """What keeps ``items`` from being every ``expected`` item exactly once (empty = none)."""
    counts = Counter(str(i) for i in items)
    twice = sorted(i for i, c in counts.items() if c > 1)
    missing = sorted(set(map(str, expected)) - set(counts))
    extra = sorted(set(counts) - set(map(str, expected)))
    out = []
    if twice:
        out.append(f"{len(twice)} item(s) held out more than once, e.g. {twice[:3]}")
    if missing:
        out.append(f"{len(missing)} item(s) never held out, e.g. {missing[:3]}")
    if extra:
        out.append(f"{len(extra)} item(s) not in the data, e.g. {extra[:3]}")
    return out


def data_but_fold(data, source: str | None = None) -> dict:
    """The data config of a ``heldout.npz`` (its JSON) spelt out (either layout: :func:`full_data_config`), less
    the fold; ``source``: the file, named by the error for a parked option in use."""
    data = full_data_config(json.loads(str(data)), source)
    data["split"] = {k: v for k, v in dict(data.get("split") or {}).items() if k != "fold"}
    return data


def pool(run_dirs, strict: bool = True) -> dict[str, np.ndarray]:
    """Merge the ``heldout.npz`` of every fold into one set (items sorted by id). Raises ValueError
    when the folds disagree on the data or the source, or (``strict``) when some expected item is
    missing or appears twice."""
    folds = [load_heldout(d) for d in run_dirs]
    if not folds:
        raise ValueError("no run dirs given")
    data = [data_but_fold(f["data"], str(d)) for f, d in zip(folds, run_dirs)]  # every setting but the fold
    differ = {"data": any(d != data[0] for d in data[1:])}  # (files of either config layout)
    for key in ("source", "expected"):
        differ[key] = any(not np.array_equal(f[key], folds[0][key]) for f in folds[1:])
    for key in ("data", "source", "expected"):
        if differ[key]:
            raise ValueError(f"the runs differ in '{key}': pool only the folds of one cross-validation")
    merged = {k: np.concatenate([f[k] for f in folds]) for k in (*IMAGES, "subject", "pose", "view", "item")}
    problems = coverage_problems(merged["item"], folds[0]["expected"])
    if problems and strict:
        raise ValueError("pooled held-out items do not cover the data once: " + "; ".join(problems))
    order = np.argsort(merged["item"], kind="stable")
    merged = {k: v[order] for k, v in merged.items()}
    merged.update(source=folds[0]["source"], data=folds[0]["data"], expected=folds[0]["expected"],
                  settings=folds[0].get("settings", np.array("{}")),
                  folds=np.array(sorted(int(f["fold"]) for f in folds)))
    return merged
