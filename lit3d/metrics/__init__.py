"""Metrics of every task. The point-cloud surface measures are importable from here
(:mod:`lit3d.metrics.clouds`: ``chamfer_distance``, ``f_score``, ``normal_consistency``), imported on
first use so that ``import lit3d.metrics.<module>`` stays as light as that module."""
from __future__ import annotations

import importlib

_CLOUDS = ("CHAMFER_CONVENTIONS", "THRESHOLD_MODES", "bbox_diagonal", "chamfer_distance", "f_score",
           "normal_consistency")


def __getattr__(name: str):
    if name in _CLOUDS:
        return getattr(importlib.import_module("lit3d.metrics.clouds"), name)
    raise AttributeError(f"module 'lit3d.metrics' has no attribute {name!r}")


__all__ = list(_CLOUDS)
