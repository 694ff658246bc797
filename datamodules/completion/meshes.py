"""Completion items from real CAD models (``data.source=meshes | shapenet | sweethome3d | installed``).

The plan is the procedural one (:func:`datamodules.completion.plan.synth_items`: the same splits,
view sets, views per shape and names) with a real model behind every item of a category that
has at least ``min_models`` models (with ``source=meshes``, a folder of your own: at least one model,
:func:`attach_models` ``keep_small``); such a category's models are split by model id
(:func:`datamodules.completion.cad_models.split_models`: train / val / test, test shared by
test_same and test_cross as in 3D-RecGAN++), and unseen categories, never trained on, use all
of theirs. A category with fewer models keeps procedural shapes, and the manifest says so
(``fallback``). Each item is rendered and voxelised by
:func:`datamodules.completion.plan.view_pair` like a procedural one.
:func:`prepare_mesh_items` takes the :class:`~datamodules.completion.plan.ItemSpec` and a
:class:`MeshSpec` (the mesh source's own settings), not the DataModule.
"""
from __future__ import annotations

import logging
from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass, fields
from pathlib import Path

from tqdm.auto import tqdm

from datamodules.cache import CacheBuilder, DataError, stable_int_seed
from datamodules.completion.cad_models import (
    CadModel, category_folders, index_mesh_folder, index_shapenet, split_models,
)
from datamodules.completion.catalogues import index_installed
from datamodules.completion.mesh_shapes import mesh_shape
from datamodules.completion.plan import DataConfigError, ItemSpec, synth_pair, view_pair
from datamodules.completion.sweethome3d import credits_markdown, index_sweethome3d
from datamodules.completion.voxel_cache import save_pair
from datamodules.processes import spawned_results
from lit3d.sensing.sensor import make_sensor
from lit3d.utils.shapenet_categories import SEEN_CATEGORIES, UNSEEN_CATEGORIES
from lit3d.utils.stops import check_stop

log = logging.getLogger("lit3d.data")

MESH_SOURCES = ("meshes", "shapenet", "sweethome3d", "installed")
SPLIT_GROUP = {"train": "train", "val": "val", "test_same": "test", "test_cross": "test"}


@dataclass(frozen=True)
class MeshSpec:
    """The settings of a mesh source: ``source`` (meshes | shapenet | sweethome3d), ``root`` (None:
    the installed Sweet Home 3D catalogues), ``model_split`` (train/val/test fractions of a seen
    category's models), ``min_models`` (fewer: the category keeps procedural shapes), ``up_axis`` and
    ``procedural_share`` (that share of the training items, chosen by item, made from procedural shapes
    instead: a mix of real and procedural training data; validation and test items stay real)."""

    source: str
    root: Path | None
    model_split: Mapping[str, float]
    min_models: int
    up_axis: str
    procedural_share: float = 0.0  # share of the training items drawn from procedural shapes (a mix)


def index_models(source: str, root: str | Path | None) -> tuple[list[CadModel], list[dict]]:
    """(models, dropped) of a mesh source; ``root`` None means the installed catalogues (sweethome3d;
    installed: the unpacked Debian packages of :mod:`datamodules.completion.catalogues`)."""
    if source == "sweethome3d":
        return index_sweethome3d(root)
    if source == "installed":
        return index_installed(root)
    if root is None:
        raise DataError(f"data.source={source} needs a folder: set data.root=PATH")
    return (index_mesh_folder if source == "meshes" else index_shapenet)(root)


def folder_plan_categories(root: Path | None, categories=None, unseen_categories=None) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """(seen, unseen) categories of the plan of a folder of your own (``data.source=meshes``).

    ``categories`` None: every category folder under ``root`` (:func:`~datamodules.completion.cad_models.category_folders`)
    but the unseen ones; ``unseen_categories`` None: the folders of the thesis's unseen categories. Given
    names must be thesis categories or folders (a user category made unseen: ``data.categories.unseen=[animal]``).

    Raises:
        DataConfigError: no root, or a given name that is neither (naming it and the folders).
    """
    if root is None:
        raise DataConfigError("data.source=meshes needs a folder: set data.root=PATH")
    found = list(category_folders(root))
    known = set(found) | set(SEEN_CATEGORIES) | set(UNSEEN_CATEGORIES)
    for key, chosen in (("categories.seen", categories), ("categories.unseen", unseen_categories)):
        bad = [str(c) for c in chosen or () if str(c) not in known]
        if bad:
            raise DataConfigError(f"data.{key}: {bad} are neither thesis categories nor category folders of {root} "
                                  f"(its folders: {', '.join(found) or 'none'})")
    chosen = [str(c) for c in categories or ()]
    unseen = tuple(str(c) for c in unseen_categories) if unseen_categories is not None else tuple(
        c for c in found if c in UNSEEN_CATEGORIES and c not in chosen)
    seen = tuple(chosen) if categories is not None else tuple(c for c in found if c not in unseen)
    return seen, unseen


def procedural_draw(item: dict, seed: int) -> float:
    """A number in [0, 1) fixed by the item's file name and the data seed (the mix's draw per item)."""
    return stable_int_seed(seed, "procedural_share", item["file"]) / 2**31


def attach_models(items: list[dict], models: list[CadModel], seen: tuple[str, ...], fractions: dict[str, float],
                  seed: int, min_models: int, procedural_share: float = 0.0,
                  keep_small: bool = False) -> tuple[list[dict], dict[str, str]]:
    """Give every planned item of a category with enough models a ``model_id`` (training items whose
    :func:`procedural_draw` is below ``procedural_share`` stay procedural).

    ``keep_small`` (a folder of your own, ``data.source=meshes``): a category with at least one but
    fewer than ``min_models`` models still uses its models; its items of a split that the model split
    left without a model are left out (:func:`small_category_notes` says which).
    Returns the items (those of fallback categories unchanged: procedural) and
    ``{category: "procedural (N real models < min_models)"}`` for the categories that fell back.
    """
    by_cat: dict[str, list[CadModel]] = {}
    for m in models:
        by_cat.setdefault(m.category, []).append(m)
    groups = split_models([m for m in models if m.category in seen], fractions, seed)
    fallback = {}
    for cat in sorted({it["category"] for it in items}):
        n = len(by_cat.get(cat, []))
        if n < min_models and not (keep_small and n > 0):
            fallback[cat] = f"procedural ({n} real models < data.meshes.min_models={min_models})"
    pools: dict[tuple[str, str], list[str]] = {}
    for cat, ms in by_cat.items():
        for m in sorted(ms, key=lambda m: m.model_id):
            group = groups.get(m.model_id, "unseen") if cat in seen else "unseen"
            pools.setdefault((cat, group), []).append(m.model_id)
    out = []
    for it in items:
        cat = it["category"]
        if cat in fallback or (procedural_share > 0 and it["split"] == "train"
                                and procedural_draw(it, seed) < procedural_share):
            out.append({**it, "shape_source": "procedural"})
            continue
        group = SPLIT_GROUP.get(it["split"], "unseen")
        pool = pools.get((cat, group))
        if not pool and keep_small and len(by_cat.get(cat, [])) < min_models:
            continue  # a small category of your own: no model in this split group
        if not pool:
            raise DataError(f"category {cat}: no {group} models after the model split; "
                            f"raise data.meshes.min_models or change data.meshes.model_split")
        model_id = pool[it["shape_index"] % len(pool)]
        out.append({**it, "shape_source": "model", "model_id": model_id})
    return out, fallback


def small_category_notes(planned: list[dict], kept: list[dict], models: list[CadModel], min_models: int) -> dict[str, str]:
    """``{category: what happens}`` for the categories with models but fewer than ``min_models`` whose
    items are real (:func:`attach_models` with ``keep_small``): how many models, and the splits left without one."""
    counts = Counter(m.category for m in models)
    real = {it["category"] for it in kept if it.get("shape_source") == "model"}
    notes = {}
    for cat in sorted(c for c in real if counts[c] < min_models):
        lost = Counter(it["split"] for it in planned if it["category"] == cat) - Counter(
            it["split"] for it in kept if it["category"] == cat)
        what = f"{counts[cat]} models (fewer than data.meshes.min_models={min_models}): its own models are used"
        if lost:
            what += (", no model left for " + ", ".join(f"{s} ({n} items left out)" for s, n in sorted(lost.items())))
        notes[cat] = what
    return notes


def make_pairs(job: dict) -> list[tuple[str, str | None]]:
    """Worker: generate and save every item of ``job`` (items of one or more models).

    ``job``: items, models ({id: CadModel record}), data_dir, seed, target_res, input_factor,
    render_factor, sensor (dict), compress, up_axis. Returns ``[(file, error or None)]``.
    """
    sensor = make_sensor(job["sensor"])
    done, loaded = [], {}
    for it in job["items"]:
        try:
            if it.get("shape_source") == "model":
                mid = it["model_id"]
                if mid not in loaded:
                    loaded.clear()
                    loaded[mid] = mesh_shape(CadModel(**job["models"][mid]), job["up_axis"])
                inp, tgt = view_pair(loaded[mid], it, job["seed"], job["target_res"], job["input_factor"],
                                     job["render_factor"], sensor)
            else:
                inp, tgt = synth_pair(it, job["seed"], job["target_res"], job["input_factor"], job["render_factor"], sensor)
        except DataError as exc:
            done.append((it["file"], str(exc)))
            continue
        save_pair(Path(job["data_dir"]) / it["file"], inp, tgt, compress=job["compress"])
        done.append((it["file"], None))
    return done


def model_fields(m: CadModel) -> dict:
    """The constructor fields of a CadModel but ``extra`` (picklable, for worker jobs)."""
    return {f.name: getattr(m, f.name) for f in fields(m) if f.name != "extra"}


def summary(models: list[CadModel], items: list[dict]) -> dict:
    """Counts for the manifest: models per category, and models used per split."""
    used: dict[str, set] = {}
    for it in items:
        if it.get("model_id"):
            used.setdefault(it["split"], set()).add(it["model_id"])
    return {"models_per_category": dict(sorted(Counter(m.category for m in models).items())),
            "models_used_per_split": {s: len(v) for s, v in sorted(used.items())}}


def _run_jobs(jobs: list[dict], workers: int):
    """Run the worker jobs in-process (workers <= 1) or in ``workers`` spawned processes."""
    if workers <= 1:
        for job in jobs:
            yield make_pairs(job)
        return
    yield from spawned_results(make_pairs, [(job,) for job in jobs], workers)


def prepare_mesh_items(builder: CacheBuilder, spec: ItemSpec, mesh: MeshSpec, skip_bad: bool = False,
                       workers: int = 0, progress: bool = True) -> tuple[list[dict], dict]:
    """Plan, render and save the items of a mesh source into ``builder``; (items, manifest extra).

    ``spec``: the plan and the bytes of each item; ``mesh``: the source, its models and their split;
    ``skip_bad``: skip the items of unreadable models (else the first raises :class:`DataError`);
    ``workers``: render in that many spawned processes (0 or 1: in this one).
    """
    models, dropped = index_models(mesh.source, mesh.root)
    planned, own = spec.items(), mesh.source == "meshes"
    items, fallback = attach_models(planned, models, spec.categories, dict(mesh.model_split), spec.seed,
                                    mesh.min_models, mesh.procedural_share, keep_small=own)
    for cat, why in fallback.items():
        log.warning("data.source=%s: %s keeps %s", mesh.source, cat, why)
    small = small_category_notes(planned, items, models, mesh.min_models) if own else {}
    for cat, what in small.items():
        log.warning("data.source=%s: category %s has %s", mesh.source, cat, what)
    if spec.sizes.get("train") and not any(it["split"] == "train" for it in items):
        raise DataError(f"{mesh.root}: no training item left (categories {', '.join(spec.categories)}); "
                        "add models or lower data.meshes.min_models")
    by_id = {m.model_id: m for m in models}
    todo = sorted((it for it in items if not builder.has(it["file"])), key=lambda it: (it.get("model_id", ""), it["file"]))
    jobs, chunk = [], []
    for it in todo:  # jobs of whole models, about 8 items each
        if chunk and len(chunk) >= 8 and it.get("model_id") != chunk[-1].get("model_id"):
            jobs.append(chunk)
            chunk = []
        chunk.append(it)
    if chunk:
        jobs.append(chunk)
    base = {"data_dir": str(builder.root), "seed": spec.seed, "target_res": spec.target_res,
            "input_factor": spec.input_factor, "render_factor": spec.render_factor, "sensor": spec.sensor.as_dict(),
            "compress": spec.compress, "up_axis": mesh.up_axis}
    jobs = [{**base, "items": c, "models": {it["model_id"]: model_fields(by_id[it["model_id"]])
                                            for it in c if it.get("model_id")}} for c in jobs]
    bad: dict[str, str] = {}
    builder.total_items = len(items)
    bar = tqdm(total=len(todo), desc=f"completion {mesh.source}", unit="item", disable=not progress, dynamic_ncols=True)
    for results in _run_jobs(jobs, workers):
        for file, error in results:
            if error is not None:
                if not skip_bad:
                    raise DataError(error)
                bad[file] = error
        bar.update(len(results))
        check_stop()  # Ctrl-C or SIGTERM: stop after this job (lit3d.utils.stops)
    bar.close()
    if bad:
        log.warning("skipped %d item(s) of unreadable models (data.prepare.skip_bad=true)", len(bad))
    items = [it for it in items if it["file"] not in bad]
    used = sorted({it["model_id"] for it in items if it.get("model_id")})
    kept = [by_id[i] for i in used]
    if mesh.source in ("sweethome3d", "installed"):
        (builder.root / "CREDITS.md").write_text(credits_markdown(kept))
    extra = {"skipped": sorted(set(bad.values())), "fallback": fallback, "small_categories": small, "dropped": dropped,
             "models": [m.record() for m in kept], **summary(models, items)}
    return items, extra
