"""Feature tables of the quality set's mesh pairs: one ``name -> float`` JSON per pair.

:func:`resolve_feature_fn` picks the feature function (the renderer's
``lit3d.features.table.feature_table`` by default, or a dotted path); :func:`write_feature_tables`
computes the tables still missing (in ``workers`` processes), each written atomically as soon as
it is done, so an interrupted preparation resumes with the pairs still missing (Ctrl-C or SIGTERM
stops an in-process preparation before the next pair, :mod:`lit3d.utils.stops`).
"""
from __future__ import annotations

import json
import warnings
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

from datamodules.cache import DataError
from lit3d.features.table import feature_config, feature_table
from lit3d.utils.io import atomic_write_text
from lit3d.utils.progress import progress
from lit3d.utils.stops import check_stop

FeatureFn = Callable[[Path, Path], Mapping[str, float]]


def resolve_feature_fn(spec: str | None, options: Mapping[str, Any] | None = None) -> FeatureFn:
    """``None`` -> the renderer's cached feature table (``lit3d.features.table.feature_table``
    with :func:`lit3d.features.table.feature_config` of ``options``; ``options["cache_dir"]`` = its JSON cache);
    else a dotted path to ``fn(ref_path, dist_path, **options) -> dict``."""
    options = dict(options or {})
    if spec is None:
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


def feature_file(item: str) -> str:
    """Path of a pair's feature table relative to the cache folder (``features/<shape>__<name>.json``)."""
    return "features/" + item.replace("/", "__") + ".json"


def write_feature_tables(root: Path, pairs: Sequence[dict], spec: str | None, options: Mapping[str, Any] | None,
                         workers: int = 0, skip_bad: bool = False) -> tuple[list[dict], list[dict], list[str]]:
    """(tables, pairs kept, skip messages) for ``pairs`` (dicts with item / reference / distorted).

    Tables already in ``root`` are read, not recomputed. A pair whose meshes fail raises
    :class:`DataError` (naming the item and the file), or is skipped with a warning when ``skip_bad``.
    """
    options = dict(options or {})
    jobs = [(p["item"], p["reference"], p["distorted"], str(root / feature_file(p["item"])), spec, options)
            for p in pairs if not (root / feature_file(p["item"])).is_file()]
    if jobs and workers > 1:
        with ProcessPoolExecutor(workers) as ex:
            results = list(progress(ex.map(_feature_job, jobs), "quality feature tables", total=len(jobs)))
    else:
        results = []
        for job in progress(jobs, "quality feature tables"):
            check_stop()  # Ctrl-C or SIGTERM: stop before the next pair (lit3d.utils.stops)
            results.append(_feature_job(job))
    errors = {i: f"{i}: {e}" for i, e in results if e}
    if errors and not skip_bad:
        raise DataError(f"feature extraction failed for {len(errors)} pair(s); first: {next(iter(errors.values()))}")
    for msg in errors.values():
        warnings.warn(f"skipping pair {msg}", stacklevel=3)
    kept = [p for p in pairs if p["item"] not in errors]
    if not kept:
        raise DataError(f"{root}: no pair left after skipping {len(errors)} bad one(s)")
    tables = [json.loads((root / feature_file(p["item"])).read_text()) for p in kept]
    return tables, kept, list(errors.values())
