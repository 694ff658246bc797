"""How the items of each completion data source are prepared into a cache folder.

One function per source, each ``(builder, spec, ...) -> (items, manifest extra)`` and given only
what it needs (:class:`~datamodules.completion.plan.ItemSpec` and the source's own settings),
never the DataModule:

- :func:`prepare_synth_items` (``source=synth``): procedural shapes of the plan;
- :func:`prepare_recgan_items` (``source=recgan``): the 3D-RecGAN++ release converted
  (:mod:`datamodules.completion.recgan`);
- :func:`datamodules.completion.meshes.prepare_mesh_items` (``source=meshes | shapenet |
  sweethome3d``): real CAD models behind the plan's items.

Every item is written with :func:`~datamodules.completion.voxel_cache.save_pair` (atomic); items
already on disk are kept, so an interrupted preparation resumes where it stopped. Ctrl-C or SIGTERM
stops a preparation at the next item (the builder's ``path()``/``has()`` are stop points,
:mod:`lit3d.utils.stops`).
"""
from __future__ import annotations

import logging
from collections.abc import Iterable
from pathlib import Path

from tqdm.auto import tqdm

from datamodules.cache import CacheBuilder, DataError
from datamodules.completion.plan import ItemSpec, synth_pair
from datamodules.completion.recgan import assign_splits, convert_pair, index_recgan
from datamodules.completion.voxel_cache import save_pair

log = logging.getLogger("lit3d.data")


def progress_bar(iterable: Iterable, total: int, desc: str, on: bool = True):
    """A tqdm bar over ``iterable`` (off: the iterable itself, counted by nothing)."""
    return tqdm(iterable, total=total, desc=desc, unit="item", disable=not on, dynamic_ncols=True)


def prepare_synth_items(builder: CacheBuilder, spec: ItemSpec, progress: bool = True) -> tuple[list[dict], dict]:
    """Generate the planned procedural items still missing from ``builder``; (items, manifest extra)."""
    items = spec.items()
    builder.total_items = len(items)  # named by the stop line of a Ctrl-C (each builder.path() is a stop point)
    todo = [it for it in items if not builder.has(it["file"])]
    if len(todo) < len(items):
        log.info("%s: %d of %d items already prepared", builder.root, len(items) - len(todo), len(items))
    for it in progress_bar(todo, len(todo), "completion synth", progress):
        inp, tgt = synth_pair(it, spec.seed, spec.target_res, spec.input_factor, spec.render_factor, spec.sensor)
        save_pair(builder.path(it["file"]), inp, tgt, compress=spec.compress)
    return items, {"skipped": []}


def prepare_recgan_items(builder: CacheBuilder, spec: ItemSpec, root: Path, raw_res: int, val_fraction: float,
                         skip_bad: bool = False, progress: bool = True) -> tuple[list[dict], dict]:
    """Convert the 3D-RecGAN++ release at ``root`` into ``builder``: its pairs, split by shape id
    (``val_fraction`` of the training ids held out), centred to ``raw_res``^3 and pooled to the spec's
    grids; uses the spec's categories, seed, grid sizes and compression (not its sizes or sensor).
    A bad file raises :class:`DataError`, or with ``skip_bad`` is skipped and listed in ``skipped``."""
    pairs, problems = index_recgan(root, skip_bad=skip_bad)
    planned = assign_splits(pairs, spec.categories, spec.unseen_categories, val_fraction, spec.seed)
    input_res = spec.target_res // spec.input_factor
    builder.total_items = len(planned)  # each builder.has() below is a stop point (Ctrl-C, SIGTERM)
    items = []
    for split, p in progress_bar(planned, len(planned), "completion recgan", progress):
        it = {"name": p.name, "split": split, "category": p.category, "view_set": p.view_set,
              "shape_id": p.shape_id, "view": p.view, "source_folder": p.folder,
              "input_file": str(p.input_path.relative_to(root)),
              "file": f"items/{split}/{p.name}_{p.view_set}.npz"}
        if not builder.has(it["file"]):
            try:
                inp, tgt = convert_pair(p, raw_res, spec.target_res, input_res)
            except DataError as exc:
                if not skip_bad:
                    raise
                log.warning("skipping: %s", exc)
                problems.append(str(exc))
                continue
            save_pair(builder.path(it["file"]), inp, tgt, compress=spec.compress)
        items.append(it)
    if problems:
        log.warning("%s: skipped %d bad file(s)", root, len(problems))
    return items, {"skipped": problems}
