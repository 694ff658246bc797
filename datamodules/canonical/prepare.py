"""Writing a canonical cache's subject files (``subjects/<subject>.npz``), in this process or in
``prepare_workers`` spawned processes (subjects are independent: each file is one subject's
:meth:`~datamodules.canonical.rendering.PairRenderer.render_subject`, saved atomically).

A worker rebuilds the source and renderer from the DataModule's hyper-parameters (a plain dict:
sources hold modules and meshes that do not pickle) once per process. The first subject that fails
raises its :class:`~datamodules.cache.DataError` here, after the jobs not yet started are dropped;
files already written stay, so a rerun renders only the missing subjects.
"""
from __future__ import annotations

import json
from collections.abc import Callable, Mapping
from functools import lru_cache

import numpy as np
from lightning.fabric.utilities.data import AttributeDict
from tqdm import tqdm

from datamodules.cache import CacheBuilder, atomic_save_npz
from datamodules.canonical.rendering import PairRenderer
from datamodules.canonical.sources import make_source
from datamodules.processes import spawned_results
from lit3d.utils.stops import check_stop

SUBJECTS_DIR = "subjects"  # the cache's item folder


def subject_file(subject: str) -> str:
    """The cache-relative file of one subject."""
    return f"{SUBJECTS_DIR}/{subject}.npz"


@lru_cache(maxsize=2)
def _worker_renderer(hp_json: str) -> PairRenderer:
    """The renderer of hyper-parameters ``hp_json`` (JSON of a dict), built once per worker process."""
    hp = AttributeDict(json.loads(hp_json))
    return PairRenderer(make_source(hp), hp)


def _render_job(hp_json: str, subject: str, path: str) -> str:
    """Render ``subject`` and save its arrays to ``path`` (atomic); returns ``subject``."""
    atomic_save_npz(path, **_worker_renderer(hp_json).render_subject(subject))
    return subject


def write_subject_files(builder: CacheBuilder, subjects: list[str], render: Callable[[str], dict],
                        hp: Mapping, workers: int = 0) -> list[str]:
    """Render every subject of ``subjects`` missing from ``builder`` (``render(subject) -> arrays`` in this
    process when ``workers`` <= 1, else ``workers`` spawned processes built from ``hp``); returns the poses
    skipped by ``skip_bad`` over all subject files, in subject order."""
    todo = [s for s in subjects if not builder.has(subject_file(s))]
    if workers <= 1 or len(todo) <= 1:
        for s in tqdm(todo, desc="render canonical pairs", leave=False):
            atomic_save_npz(builder.path(subject_file(s)), **render(s))
    else:
        hp_json = json.dumps(dict(hp), sort_keys=True)  # plain values (build_datamodule); tuples become lists
        jobs = [(hp_json, s, str(builder.path(subject_file(s)))) for s in todo]
        for _ in tqdm(spawned_results(_render_job, jobs, workers), total=len(jobs), desc="render canonical pairs",
                      leave=False):
            check_stop()  # Ctrl-C or SIGTERM: stop between finished subjects
    skipped = []
    for s in subjects:
        with np.load(builder.path(subject_file(s)), allow_pickle=False) as z:
            skipped += [str(m) for m in z["skipped"]] if "skipped" in z.files else []
    return skipped
