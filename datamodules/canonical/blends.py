"""Blended training poses: new poses of a subject made by mixing the vertices of two of its
training poses, for sources whose poses of one subject share one mesh connectivity (TOSCA: vertex
``i`` of ``cat3`` is vertex ``i`` of ``cat0``).

A blend of poses ``a`` and ``b`` (either may be the canonical pose, which is every fold's training
target anyway) with weight ``t`` is the mesh ``(1 - t) V_a + t V_b`` with ``a``'s faces, then
centred, scaled and turned by the view convention like any other pose, and rendered from every
azimuth. Endpoints are only the fold's *training* poses (and the canonical one), so no validation
or test pose leaks into training. The blends are drawn (seeded by the data seed and the fold) and
rendered in memory at ``setup``, about 30 ms a pose with 5 views: they depend on the fold, so they
are not cached. Linear blending shortens limbs that turn between the two poses; it is a training
augmentation, never an evaluation item.

Blend poses get ids ``BLEND_BASE + k`` (``k`` counts the subject's blends), far above any real
pose id, in the same ``"<pose>_<view>"`` keys of the in-memory cache.
"""
from __future__ import annotations

from collections.abc import Callable

import numpy as np

from datamodules.cache import DataError

BLEND_BASE = 10_000  # id of a subject's first blended pose


def draw_blends(endpoints: list, n: int, rng: np.random.Generator,
                t_range: tuple[float, float] = (0.15, 0.85)) -> list[tuple]:
    """``n`` triples ``(a, b, t)``: two distinct endpoints (poses) and a weight drawn uniformly from
    ``t_range``; empty when there are fewer than two endpoints."""
    if len(endpoints) < 2 or n <= 0:
        return []
    out = []
    for _ in range(n):
        i, j = rng.choice(len(endpoints), 2, replace=False)
        out.append((endpoints[int(i)], endpoints[int(j)], float(rng.uniform(*t_range))))
    return out


def blend_vertices(va: np.ndarray, vb: np.ndarray, t: float, where: str) -> np.ndarray:
    """``(V, 3)`` vertices ``(1 - t) va + t vb``; DataError naming ``where`` when the counts differ."""
    if va.shape != vb.shape:
        raise DataError(f"{where}: cannot blend poses with different vertex counts "
                        f"({va.shape[0]} vs {vb.shape[0]}); blend_poses needs one connectivity per subject")
    return (1.0 - t) * va + t * vb


def add_blends(cache: dict[str, dict], train_pairs: list[tuple], n_per_subject: int, seed: int, fold: int,
               mesh: Callable[[str, object], tuple[np.ndarray, np.ndarray]],
               render_views: Callable[[str, np.ndarray, np.ndarray], list[tuple[np.ndarray, np.ndarray]]]) -> list[tuple]:
    """Draw and render ``n_per_subject`` blends for every subject of ``train_pairs`` and put their
    images into ``cache[subject]["depth"|"mask"]`` under ``"<id>_<view>"``.

    Args:
        cache: the DataModule's in-memory cache (``{"depth", "mask"}`` dicts of ``(S, S)`` float32).
        train_pairs: the fold's training ``(subject, pose)`` pairs: the only endpoints besides
            each subject's canonical pose.
        mesh: ``(subject, pose) -> (V, 3), (F, 3)`` raw (unnormalised) mesh; ``pose="canonical"`` ok.
        render_views: ``(subject, V, F) -> [(depth (S, S), mask (S, S)) per view]`` of the raw
            mesh, normalised and turned as the DataModule renders poses; DataError for a bad image.

    Returns:
        The ``(subject, blend_id)`` pairs added, for the training records.
    """
    rng = np.random.default_rng([int(seed), int(fold), 71])
    by_subject: dict[str, list] = {}
    for s, p in train_pairs:
        by_subject.setdefault(s, []).append(p)
    added = []
    for s in sorted(by_subject):
        if s not in cache:
            continue
        draws = draw_blends(["canonical"] + sorted(by_subject[s]), n_per_subject, rng)
        verts = {}
        for k, (a, b, t) in enumerate(draws):
            for p in (a, b):
                if p not in verts:
                    verts[p] = mesh(s, p)
            where = f"{s} blend {k} (poses {a}, {b}, t={t:.2f})"
            v = blend_vertices(verts[a][0], verts[b][0], t, where)
            pid = BLEND_BASE + k
            try:
                views = render_views(s, v, verts[a][1])
            except DataError as exc:
                raise DataError(f"{where}: {exc}") from exc
            for view, (d, m) in enumerate(views):
                cache[s]["depth"][f"{pid}_{view}"] = d.astype(np.float16).astype(np.float32)  # as cached poses
                cache[s]["mask"][f"{pid}_{view}"] = m.astype(np.float32)
            added.append((s, pid))
    return added
