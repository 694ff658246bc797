"""Writing a canonical cache's subject files (``subjects/<subject>.npz``), in this process or in
``prepare_workers`` spawned processes (subjects are independent: each file is one subject's
:meth:`~datamodules.canonical.rendering.PairRenderer.render_subject`, saved atomically).

A worker rebuilds the source and renderer from their settings (:class:`RenderJob`, frozen dataclasses:
sources hold modules and meshes that do not pickle) once per process. The first subject that fails
raises its :class:`~datamodules.cache.DataError` here, after the jobs not yet started are dropped;
files already written stay, so a rerun renders only the missing subjects.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from tqdm import tqdm

from datamodules.cache import CacheBuilder, atomic_save_npz
from datamodules.canonical.rendering import PairRenderer
from datamodules.canonical.settings import RenderSettings, SourceSettings
from datamodules.canonical.sources import build_source
from datamodules.processes import spawned_results
from lit3d.utils.stops import check_stop

SUBJECTS_DIR = "subjects"  # the cache's item folder


def subject_file(subject: str) -> str:
    """The cache-relative file of one subject."""
    return f"{SUBJECTS_DIR}/{subject}.npz"


@dataclass(frozen=True)
class RenderJob:
    """What a worker process needs to build the renderer: the source's settings and ``root``, the
    rendering settings, the image size and ``skip_bad`` (hashable and picklable)."""

    source: SourceSettings
    root: str | None
    render: RenderSettings
    image_size: int
    skip_bad: bool

    def renderer(self) -> PairRenderer:
        return PairRenderer(build_source(self.source, self.root), self.render, self.image_size, self.skip_bad)


@lru_cache(maxsize=2)
def _worker_renderer(job: RenderJob) -> PairRenderer:
    """The renderer of ``job``, built once per worker process."""
    return job.renderer()


def _render_job(job: RenderJob, subject: str, path: str) -> str:
    """Render ``subject`` and save its arrays to ``path`` (atomic); returns ``subject``."""
    atomic_save_npz(path, **_worker_renderer(job).render_subject(subject))
    return subject


def write_subject_files(builder: CacheBuilder, subjects: list[str], render: Callable[[str], dict],
                        job: RenderJob, workers: int = 0) -> list[str]:
    """Render every subject of ``subjects`` missing from ``builder`` (``render(subject) -> arrays`` in this
    process when ``workers`` <= 1, else ``workers`` spawned processes built from ``job``); returns the poses
    skipped by ``skip_bad`` over all subject files, in subject order."""
    todo = [s for s in subjects if not builder.has(subject_file(s))]
    if workers <= 1 or len(todo) <= 1:
        for s in tqdm(todo, desc="render canonical pairs", leave=False):
            atomic_save_npz(builder.path(subject_file(s)), **render(s))
    else:
        jobs = [(job, s, str(builder.path(subject_file(s)))) for s in todo]
        for _ in tqdm(spawned_results(_render_job, jobs, workers), total=len(jobs), desc="render canonical pairs",
                      leave=False):
            check_stop()  # Ctrl-C or SIGTERM: stop between finished subjects
    skipped = []
    for s in subjects:
        with np.load(builder.path(subject_file(s)), allow_pickle=False) as z:
            skipped += [str(m) for m in z["skipped"]] if "skipped" in z.files else []
    return skipped
