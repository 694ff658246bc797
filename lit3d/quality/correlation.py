"""Correlations of predicted and target scores, per reference shape and averaged over shapes.

Pearson and Spearman come from :mod:`scipy.stats`; the one rule added here: a side that is
constant (or shorter than two samples) gives 0.0, not NaN (no association is measurable, and
a mean over shapes must stay defined).
"""
from __future__ import annotations

import math

import numpy as np
import scipy.stats


def _measurable(a: np.ndarray, b: np.ndarray) -> bool:
    return a.size >= 2 and bool(np.ptp(a) > 0) and bool(np.ptp(b) > 0)


def _finite_clipped(r: float) -> float:
    return float(np.clip(r, -1.0, 1.0)) if math.isfinite(r) else 0.0


def pearson(a: np.ndarray, b: np.ndarray) -> float:
    """Pearson r of two (N,) arrays (float64); 0.0 when either side is constant or N < 2."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    if not _measurable(a, b):
        return 0.0
    return _finite_clipped(float(scipy.stats.pearsonr(a, b)[0]))


def spearman(a: np.ndarray, b: np.ndarray) -> float:
    """Spearman rho (Pearson of average ranks) of two (N,) arrays; 0.0 when either side is constant."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    if not _measurable(a, b):
        return 0.0
    return _finite_clipped(float(scipy.stats.spearmanr(a, b)[0]))


def per_shape_corr(pred: np.ndarray, target: np.ndarray, shapes: np.ndarray, kind: str = "pearson") -> dict[str, float]:
    """Shape name -> ``kind`` ("pearson" | "spearman") correlation over that shape's rows, in
    first-appearance order. pred, target: (N,) float; shapes: (N,) str."""
    fn = pearson if kind == "pearson" else spearman
    pred, target = np.asarray(pred), np.asarray(target)
    shapes = np.asarray(shapes).astype(str)
    return {s: fn(pred[shapes == s], target[shapes == s]) for s in dict.fromkeys(shapes.tolist())}


def mean_per_shape_corr(pred: np.ndarray, target: np.ndarray, shapes: np.ndarray, kind: str = "pearson") -> float:
    """Mean over shapes of :func:`per_shape_corr` (0.0 for no rows)."""
    vals = list(per_shape_corr(pred, target, shapes, kind).values())
    return float(np.mean(vals)) if vals else 0.0


def shape_corr_metrics(prefix: str, pred: np.ndarray, target: np.ndarray, shapes: np.ndarray) -> dict[str, float]:
    """``{prefix}/{kind}/{shape}`` and ``{prefix}/{kind}`` (mean over shapes) for Pearson and Spearman."""
    out: dict[str, float] = {}
    for kind in ("pearson", "spearman"):
        vals = per_shape_corr(pred, target, shapes, kind)
        out.update({f"{prefix}/{kind}/{s}": v for s, v in vals.items()})
        out[f"{prefix}/{kind}"] = float(np.mean(list(vals.values()))) if vals else float("nan")
    return out
