"""Pooled, cross-validated retrieval of the canonical task: every held-out item scored once, every
row on the same items and the same codebook seeds, mean +- sd over the seeds: :func:`run`, and at the
end of ``+sweep=canonical_cv`` the Hydra callback :class:`PooledResults`. By hand, from the checkout:
``lit3d-summary --pooled`` (:mod:`lit3d.cli.summary_canonical`).

With run dirs (one per fold, each with the ``heldout.npz`` that
:func:`lit3d.canonical.evaluator.protocol` writes), the folds are merged
(:func:`lit3d.canonical.heldout.pool`: each item held out exactly once) and the rows are the
prediction (``model`` or ``unet``), the posed input depth and the true canonical depth, plus the
mesh rows. Without run dirs the Hydra overrides after ``--`` compose the data, task and evaluation config (as
``lit3d-train`` would) and the items are every item some fold holds out
(:meth:`datamodules.canonical.CanonicalDataModule.held_out_records`): the posed-input and true
canonical depth rows plus the mesh rows, and with ``data.render.flow_targets=true`` the warp oracle
(:func:`warp_oracle`: the true canonical where the posed input sees it, the mean body elsewhere). Mesh rows
(one per held-out subject x pose, full resolution): the non-learned canonical forms
``evaluation.mesh_baselines`` (landmark geodesics, :mod:`lit3d.geometry.canonical_forms`), ShapeDNA of the
posed full mesh (the intrinsic ceiling, :func:`lit3d.geometry.spectral.shape_dna`; no codebook, so sd 0),
and chance (random distances, seeded by the codebook seed). ``--depth-row ROW=DIR``: one more depth row,
the canonical depth images that ``lit3d-reconstruct --body`` wrote for inputs named ``<subject>_pose<pose>``
(``DIR/<subject>_pose<pose>_body_canonical_depth.npy``, :func:`folder_depths`), e.g.
``--depth-row body_fit=OUT/faust_canonical`` (:mod:`studies.body.evaluate` writes that folder for FAUST).
Writes ``DIR/pooled_results.md`` (thesis table 5.x layout) and ``DIR/pooled.json`` (every seed's scores).
"""
from __future__ import annotations

import json
import logging
import time
from pathlib import Path

import numpy as np

from datamodules.canonical import CanonicalDataModule
from datamodules.canonical.flat_config import upgrade_data_config
from datamodules.canonical.dataset import CanonicalPairDataset
from lit3d.canonical.baselines import mesh_rows
from lit3d.canonical.heldout import HELDOUT_FILE, pool, settings_of
from lit3d.canonical.report import write_pooled_results
from lit3d.canonical.smoothing import SETTING, smooth_prediction, smoothing_of
from lit3d.metrics.depth import composite_depth
from lit3d.metrics.retrieval import chance_scores, mask_iou, retrieval_scores
from lit3d.retrieval.descriptor import DescriptorConfig, depth_meshes, distance_matrix_from_features, mesh_features
from lit3d.utils.config_dir import config_dir
from lit3d.utils.io import write_json

log = logging.getLogger("lit3d")

DEPTH_ROWS = ("model", "unet", "input", "target", "oracle")
SCORES = ("nn", "ft", "st", "e", "dcg")


def depth_meshes_of(pooled: dict, cfg, mask_threshold: float) -> dict[str, list]:
    """``{row: [(verts, faces)]}`` back-projected from the pooled depth images: the prediction
    (mask probability thresholded at ``mask_threshold``), the posed input, the true canonical."""
    import torch

    def meshes(d, m):
        d, m = torch.from_numpy(d.astype(np.float32)), torch.from_numpy(m.astype(np.float32))
        return depth_meshes(composite_depth(d, m).numpy(), m.numpy(), cfg)

    out = {}
    if "pred_depth" in pooled:
        pm = (pooled["pred_mask"].astype(np.float32) >= mask_threshold).astype(np.float32)
        out[str(pooled.get("source", "model"))] = meshes(pooled["pred_depth"], pm)
    out["input"] = meshes(pooled["depth"], pooled["mask"])
    out["target"] = meshes(pooled["canon_depth"], pooled["canon_mask"])
    if "vis" in pooled:
        out["oracle"] = meshes(*warp_oracle(pooled))
    return out


def warp_oracle(items: dict) -> tuple[np.ndarray, np.ndarray]:
    """Depth and mask ``(N, 1, S, S)`` float32 of a perfect warp head: the true canonical form where its
    surface is seen in the posed input (``vis``, from the flow targets), the mean canonical body of the
    items elsewhere (mask: mean canonical mask >= .5; depth: mean canonical depth over the items whose
    mask holds the pixel). Items need ``canon_depth``, ``canon_mask`` and ``vis``, one shape: ``(N, S, S)``
    or ``(N, 1, S, S)``."""
    d = np.asarray(items["canon_depth"], np.float32)
    m = (np.asarray(items["canon_mask"], np.float32) > 0.5).astype(np.float32)
    vis = (np.asarray(items["vis"], np.float32) > 0.5).astype(np.float32)
    if not d.shape == m.shape == vis.shape:
        raise ValueError(f"warp oracle: canon_depth {d.shape}, canon_mask {m.shape} and vis {vis.shape} differ")
    mean_mask = (m.mean(0, keepdims=True) >= 0.5).astype(np.float32)
    mean_depth = (d * m).sum(0, keepdims=True) / np.maximum(m.sum(0, keepdims=True), 1) * mean_mask
    mask = vis * m + (1 - vis) * mean_mask
    depth = vis * d + (1 - vis) * mean_depth
    return depth * mask, mask


FOLDER_DEPTH_SUFFIX = "_body_canonical_depth.npy"


def folder_depths(items: dict, folder, suffix: str = FOLDER_DEPTH_SUFFIX) -> np.ndarray:
    """``(N, S, S) float32`` depth images (0 = background) of the items (``subject``, ``pose``) read
    from ``folder/<subject>_pose<pose><suffix>``; raises FileNotFoundError naming the missing ones."""
    paths = [Path(folder) / f"{s}_pose{int(p)}{suffix}" for s, p in zip(items["subject"], items["pose"])]
    missing = [p.name for p in paths if not p.is_file()]
    if missing:
        raise FileNotFoundError(f"{folder}: {len(missing)} of {len(paths)} depth images missing, e.g. {missing[:3]}")
    depths = [np.load(p).astype(np.float32) for p in paths]
    return np.stack([d.reshape(d.shape[-2:]) for d in depths])


def _flat(m) -> np.ndarray:
    """``(N, 1, S, S)`` or ``(N, S, S)`` -> ``(N, S, S)``."""
    return np.asarray(m).reshape(len(m), *np.shape(m)[-2:])


def canonical_masks(items: dict) -> tuple[list[str], np.ndarray, np.ndarray]:
    """``(subject names, own (N,), canon (C, S, S))``: the sorted subject names, each item's subject
    index into them, and each subject's true canonical mask (booleans). The subject whose canonical
    mask is nearest to masks ``m`` ``(N, S, S)``: ``mask_iou(m, canon).argmax(1)``."""
    subjects = np.asarray(items["subject"]).astype(str)
    names = sorted(set(subjects.tolist()))
    truth = _flat(items["canon_mask"]) > 0.5
    canon = np.stack([truth[np.flatnonzero(subjects == s)[0]] for s in names])
    return names, np.array([names.index(s) for s in subjects]), canon


def prediction_masks(items: dict, mask_threshold: float) -> dict[str, np.ndarray]:
    """``{row: (N, S, S) booleans}``: the prediction (its source's name) thresholded, and the posed input."""
    rows = {"input": _flat(items["mask"]) > 0.5}
    if "pred_mask" in items:
        rows = {str(items.get("source", "model")): _flat(items["pred_mask"]) >= mask_threshold, **rows}
    return rows


def subject_separation(pairwise: np.ndarray, subjects: np.ndarray) -> dict[str, float]:
    """Mean of ``pairwise`` ``(N, N)`` (a similarity, e.g. mask IoU) over pairs of distinct items of
    one subject (``iou_same``; NaN when every subject has one item) and of two subjects
    (``iou_other``); ``subjects`` ``(N,)``."""
    same = subjects[:, None] == subjects[None, :]
    other_pose = same & ~np.eye(len(subjects), dtype=bool)
    return {"iou_same": float(pairwise[other_pose].mean()) if other_pose.any() else float("nan"),
            "iou_other": float(pairwise[~same].mean()) if (~same).any() else float("nan")}


def mask_match(items: dict, mask_threshold: float) -> dict[str, dict[str, float]]:
    """Descriptor-free checks of the pooled items: per depth row (the prediction and the posed
    input), the mean mask IoU with the item's true canonical mask (``iou``) and the share of items
    whose nearest true canonical mask (highest IoU among the subjects' canonical masks) is their
    own subject's (``nearest_subject``; chance = 1 / subjects), and retrieval among the row's own
    masks with distance 1 - IoU (``nn_by_mask``, ``ft_by_mask``: no codebook, so no seed), and the
    mean IoU between two of the row's masks of one subject (``iou_same``, other poses) and of two
    subjects (``iou_other``): canonical forms that keep the person have ``iou_same`` above
    ``iou_other`` (the true canonical masks: 1 against the subjects' own spread).
    Masks ``(N, 1, S, S)`` or ``(N, S, S)``."""
    subjects = np.asarray(items["subject"]).astype(str)
    truth = _flat(items["canon_mask"]) > 0.5
    _, own, canon = canonical_masks(items)
    out = {}
    for row, m in prediction_masks(items, mask_threshold).items():
        nearest = mask_iou(m, canon).argmax(1)
        out[row] = {"iou": float(np.mean([mask_iou(m[i:i + 1], truth[i:i + 1])[0, 0] for i in range(len(m))])),
                    "nearest_subject": float((nearest == own).mean())}
        pairwise = mask_iou(m, m)
        by_mask = retrieval_scores(1.0 - pairwise, subjects)
        out[row].update(nn_by_mask=float(by_mask["nn"]), ft_by_mask=float(by_mask["ft"]),
                        **subject_separation(pairwise, subjects))
    return out


def score_rows(features: dict[str, list], labels: np.ndarray, cfg, seeds, extra_dists: dict | None = None,
               chance_trials: int = 100) -> dict[str, dict[str, list[float]]]:
    """``{row: {score: [value per seed]}}``: each row's descriptor features
    (:func:`lit3d.retrieval.descriptor.mesh_features`) through a codebook per seed; ``extra_dists``
    ``{row: (n, n)}`` (seed-free, e.g. ShapeDNA) scored once per seed alike; chance per seed."""
    out: dict[str, dict[str, list[float]]] = {}
    for seed in seeds:
        per = {row: retrieval_scores(distance_matrix_from_features(f, cfg, seed), labels) for row, f in features.items()}
        per.update({row: retrieval_scores(D, labels) for row, D in (extra_dists or {}).items()})
        per["chance"] = chance_scores(labels, chance_trials, seed=int(seed))
        for row, sc in per.items():
            for k in SCORES:
                out.setdefault(row, {}).setdefault(k, []).append(float(sc[k]))
    return out


def mean_sd(values) -> tuple[float, float]:
    """Mean and sample sd (ddof=1; 0 for a single value)."""
    return float(np.mean(values)), float(np.std(values, ddof=1)) if len(values) > 1 else 0.0


def summarise(per_seed: dict[str, dict[str, list[float]]]) -> dict[str, dict[str, tuple[float, float]]]:
    """``{row: {score: (mean, sd)}}`` (:func:`mean_sd` over the seeds)."""
    return {row: {k: mean_sd(v) for k, v in sc.items()} for row, sc in per_seed.items()}


def study(items: dict, datamodule, settings: dict, seeds, rows=None, extra_depths: dict | None = None) -> dict:
    """Every row's per-seed scores on the pooled ``items`` (``subject``, ``pose`` and the depth
    images of :func:`lit3d.canonical.heldout.pool`); ``settings``: the evaluation settings ``retrieval``,
    ``mask_threshold``, ``chance_trials``, ``mesh_baselines``, ``baseline_max_vertices``,
    ``baseline_landmarks``, ``baseline_smacof_eps``. ``rows``: restrict to these row names.
    ``extra_depths``: ``{row: (N, S, S) depth}`` more depth rows (mask: depth > 0; :func:`folder_depths`)."""
    cfg = DescriptorConfig(**(settings.get("retrieval") or {}))
    want = (lambda r: rows is None or r in rows)  # noqa: E731
    labels = np.asarray(items["subject"])
    seconds, features = {}, {}
    for row, meshes in depth_meshes_of(items, cfg, settings.get("mask_threshold", 0.5)).items():
        if want(row):
            t0 = time.perf_counter()
            features[row] = mesh_features(meshes, cfg)
            seconds[row] = time.perf_counter() - t0
            log.info("%s: descriptor features of %d items, %.0fs", row, len(meshes), seconds[row])
    for row, d in (extra_depths or {}).items():
        if want(row):
            t0 = time.perf_counter()
            features[row] = mesh_features(depth_meshes(d, (d > 0).astype(np.float32), cfg), cfg)
            seconds[row] = time.perf_counter() - t0
    pairs = list(zip(items["subject"], items["pose"]))
    if len(set(pairs)) != len(pairs):  # several views per pose: mesh rows would rank other items
        log.warning("several views per pose: mesh rows skipped (they score one item per subject x pose)")
        methods = []
    else:
        methods = [m for m in [*(settings.get("mesh_baselines") or []), "shapedna"] if want(m)]
    meshes = [datamodule.normalized_mesh(str(s), int(p)) for s, p in pairs] if methods else []
    mesh_feats, dists, mesh_secs = mesh_rows(meshes, methods, cfg, settings.get("baseline_max_vertices"),
                                             settings.get("baseline_landmarks", 300),
                                             settings.get("baseline_smacof_eps", 1e-4))
    features.update(mesh_feats)
    seconds.update(mesh_secs)
    log.info("mesh rows %s: %s", methods, {k: round(v) for k, v in mesh_secs.items()})
    t0 = time.perf_counter()
    per_seed = score_rows(features, labels, cfg, seeds, dists, int(settings.get("chance_trials", 100)))
    return {"per_seed": per_seed, "summary": summarise(per_seed), "seeds": [int(s) for s in seeds],
            "n_items": int(len(labels)), "n_subjects": int(len(set(labels.tolist()))),
            "mask_match": mask_match(items, settings.get("mask_threshold", 0.5)),
            "seconds": {**seconds, "codebooks_and_scores": time.perf_counter() - t0},
            "descriptor": cfg.__dict__}


def with_smoothing(items: dict, settings: dict, sigma: float) -> dict:
    """``items`` with the prediction's depth smoothed inside its silhouette by ``sigma`` px
    (:mod:`lit3d.canonical.smoothing`), recorded in ``settings``; ValueError when the runs already
    smoothed it (their ``prediction_smooth_px``) or there is no prediction row."""
    done = smoothing_of(settings)
    if done > 0:
        raise ValueError(f"--smooth-px: the runs' predictions are already smoothed (prediction_smooth_px={done:g})")
    if "pred_depth" not in items:
        raise ValueError("--smooth-px: no prediction row to smooth (give run dirs)")
    settings[SETTING] = float(sigma)
    threshold = settings.get("mask_threshold", 0.5)
    return {**items, "pred_depth": smooth_prediction(items["pred_depth"], items["pred_mask"], sigma, threshold)}


def compose(overrides: list[str]):
    """The ``lit3d-train`` config for ``overrides`` (Hydra compose of ``conf/train.yaml`` with task=canonical)."""
    from hydra import compose as hydra_compose
    from hydra import initialize_config_dir

    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        return hydra_compose(config_name="train", overrides=["task=canonical", *overrides])


def build_datamodule(data: dict, source: str | None = None):
    """The DataModule of a data config (either layout: :func:`upgrade_data_config`; ``source``: the file it came from)."""
    data = {k: v for k, v in upgrade_data_config(data, source).items() if k != "_target_"}
    return CanonicalDataModule(**data)


def data_summary(data: dict) -> dict:
    """The data settings that a pooled result names (source, root, image size, views, split, folds, seed)."""
    data = upgrade_data_config(data)
    render, split = data.get("render") or {}, data.get("split") or {}
    return {"source": (data.get("source") or {}).get("kind"), "root": data.get("root"),
            "image_size": data.get("image_size"), "azimuths": render.get("azimuths", [0.0]),
            "view_mode": render.get("view_mode", "fixed"), "split": split.get("mode", "subject_pose"),
            "n_folds": split.get("n_folds", 3), "seed": data.get("seed")}


def run(run_dirs, seeds, out_dir, overrides=(), rows=None, strict: bool = True, mesh_baselines=None,
        fold_test: bool = False, depth_rows: dict | None = None, smooth_px: float | None = None) -> Path:
    """Pool (or, without run dirs, take every held-out item of the composed config; ``fold_test``: only
    the test split of its ``data.split.fold``), score, write ``pooled_results.md`` and ``pooled.json`` into
    ``out_dir``; returns the .md path. ``mesh_baselines``: the canonical-form rows (default: the runs'
    ``evaluation.mesh_baselines``); ``depth_rows``: ``{row: folder}`` more depth rows (:func:`folder_depths`);
    ``smooth_px``: smooth the prediction row as ``evaluation.prediction_smooth_px`` would have (:func:`with_smoothing`)."""
    from omegaconf import OmegaConf

    t0 = time.perf_counter()
    if run_dirs:
        items = pool(run_dirs, strict=strict)
        data, settings = json.loads(str(items["data"])), json.loads(str(items["settings"]))
        dm = build_datamodule(data, str(run_dirs[0]))
        meta = {"runs": [str(d) for d in run_dirs], "folds": items["folds"].tolist()}
    else:
        cfg = compose(list(overrides))
        data = OmegaConf.to_container(cfg.data, resolve=True)
        settings = settings_of({**OmegaConf.to_container(cfg.task, resolve=True),  # mask_threshold
                                **OmegaConf.to_container(cfg.evaluation, resolve=True)})
        dm = build_datamodule(data)
        dm.prepare_data()
        dm.setup()
        records = dm.splits["test"] if fold_test else dm.held_out_records()
        ds = CanonicalPairDataset(records, dm.cache, dm.subject_index)
        its = [ds[i] for i in range(len(ds))]
        items = {k: np.stack([it[k][0].numpy() for it in its]) for k in ("depth", "mask", "canon_depth", "canon_mask")}
        if all(it["has_flow"] for it in its):  # flow targets (data.render.flow_targets=true): the warp oracle row
            items["vis"] = np.stack([it["vis"][0].numpy() for it in its])
        items.update(subject=np.array([it["subject"] for it in its]), pose=np.array([it["pose"] for it in its]))
        meta = {"overrides": list(overrides)}
    if mesh_baselines is not None:
        settings["mesh_baselines"] = list(mesh_baselines)
    if smooth_px is not None:
        items = with_smoothing(items, settings, smooth_px)
    extra = {row: folder_depths(items, folder) for row, folder in (depth_rows or {}).items()}
    if extra:
        meta["depth_rows"] = {row: str(folder) for row, folder in depth_rows.items()}
    result = study(items, dm, settings, seeds, rows, extra)
    result.update(meta, data=data_summary(data),
                  settings=settings, wall_seconds=time.perf_counter() - t0)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    write_json(out_dir / "pooled.json", result)
    return write_pooled_results(result, out_dir)


def job_dirs(sweep_dir: Path) -> list[Path]:
    """The jobs of a multirun that wrote ``heldout.npz``."""
    return sorted(p for p in Path(sweep_dir).iterdir() if (p / HELDOUT_FILE).is_file())


try:
    from hydra.experimental.callback import Callback as _HydraCallback
except ImportError:  # pragma: no cover
    _HydraCallback = object


class PooledResults(_HydraCallback):
    """Hydra callback (``sweeps/canonical_cv.yaml``): when the multirun over ``data.split.fold`` ends, pool
    its jobs' held-out items and write ``pooled_results.md`` into the sweep dir."""

    def __init__(self, seeds=(0, 1, 2, 3, 4), rows=None, mesh_baselines=None):
        self.seeds, self.rows = list(seeds), (list(rows) if rows else None)
        self.mesh_baselines = list(mesh_baselines) if mesh_baselines is not None else None

    def on_multirun_end(self, config, **kwargs) -> None:
        sweep_dir = Path(config.hydra.sweep.dir)
        jobs = job_dirs(sweep_dir) if sweep_dir.is_dir() else []
        if not jobs:
            log.warning("%s: no job wrote %s; nothing pooled", sweep_dir, HELDOUT_FILE)
            return
        path = run(jobs, self.seeds, sweep_dir, rows=self.rows, mesh_baselines=self.mesh_baselines)
        print(path.read_text())
