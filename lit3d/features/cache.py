"""The feature cache: :func:`cache_path`, :func:`read_cached_table`, :func:`write_cached_table` (JSON files
``<key>.json``, written atomically and sorted) and the :class:`CacheWarning` of an unwritable cache."""
from __future__ import annotations

import json
import warnings
from pathlib import Path


from lit3d.utils.io import output_error, write_json
from lit3d.features.config import FeatureConfig, FeatureTable


def cache_path(cache_dir, key: str) -> Path | None:
    """``<cache_dir>/<key>.json`` (None without a cache folder)."""
    return Path(cache_dir) / f"{key}.json" if cache_dir is not None else None


def read_cached_table(path: Path | None, key: str) -> FeatureTable | None:
    """The table cached at ``path`` under ``key`` (``cached=True``), or None: no path, absent,
    unreadable or written under another key (then it is recomputed and overwritten)."""
    if path is None or not path.is_file():
        return None
    try:
        data = json.loads(path.read_text())
        if data.get("key") == key:
            return FeatureTable({k: float(v) for k, v in data["features"].items()}, key, cached=True)
    except (OSError, ValueError, KeyError):
        pass
    return None


class CacheWarning(UserWarning):
    """The optional feature cache could not be written (read-only, full disk...): the table is
    returned all the same, uncached; the message names the cache folder and the problem."""


def write_cached_table(path: Path | None, key: str, cfg: FeatureConfig, features: dict[str, float]) -> None:
    """Write ``{"key", "config": cfg.key_dict(), "features"}`` to ``path`` (atomic, sorted JSON;
    nothing without a path). The cache is optional: a write that fails (OSError) leaves no file
    and warns (:class:`CacheWarning`) instead of raising."""
    if path is None:
        return
    try:
        write_json(path, {"key": key, "config": cfg.key_dict(), "features": features})
    except OSError as exc:
        warnings.warn(CacheWarning(f"feature cache not written: {output_error(path.parent, exc)}"), stacklevel=2)
