"""Correlations of predicted and target scores, per reference shape and averaged over shapes,
and with bootstrap intervals over the stimuli.

Pearson (PLCC), Spearman (SROCC) and Kendall (KROCC, tau-b) come from :mod:`scipy.stats`; the one
rule added here: a side that is constant (or shorter than two samples) gives 0.0, not NaN (no
association is measurable, and a mean over shapes must stay defined).
:func:`correlation_ci` gives a correlation with its percentile bootstrap interval over the
stimuli (pairs resampled together, seeded).
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


def kendall(a: np.ndarray, b: np.ndarray) -> float:
    """Kendall tau-b of two (N,) arrays; 0.0 when either side is constant."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    if not _measurable(a, b):
        return 0.0
    return _finite_clipped(float(scipy.stats.kendalltau(a, b)[0]))


CORRELATIONS = {"srocc": spearman, "plcc": pearson, "krocc": kendall}


def _rowwise(kind: str, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """``kind`` correlation of each row pair of ``(R, N)`` arrays, ``(R,)`` float64 (0 where a row is constant):
    the same numbers as :data:`CORRELATIONS` row by row (Spearman = Pearson of average ranks; Kendall tau-b
    from the signs of all pairs), without a SciPy call per row."""
    if kind == "krocc":
        iu = np.triu_indices(x.shape[1], 1)
        dx = np.sign(x[:, :, None] - x[:, None, :])[:, iu[0], iu[1]]
        dy = np.sign(y[:, :, None] - y[:, None, :])[:, iu[0], iu[1]]
        den = np.sqrt(np.count_nonzero(dx, 1).astype(np.float64) * np.count_nonzero(dy, 1))
        s = (dx * dy).sum(1)
    else:
        if kind == "srocc":
            x, y = scipy.stats.rankdata(x, axis=1), scipy.stats.rankdata(y, axis=1)
        xc, yc = x - x.mean(1, keepdims=True), y - y.mean(1, keepdims=True)
        den = np.sqrt((xc * xc).sum(1) * (yc * yc).sum(1))
        s = (xc * yc).sum(1)
    ok = den > 0
    out = np.zeros(len(x))
    out[ok] = np.clip(s[ok] / den[ok], -1.0, 1.0)
    return out


def correlation_ci(pred: np.ndarray, target: np.ndarray, kind: str = "srocc", level: float = 0.95,
                   n_resamples: int = 2000, seed: int = 0) -> tuple[float, float, float]:
    """``(r, low, high)``: correlation ``kind`` (``srocc`` | ``plcc`` | ``krocc``) of two (N,) arrays and its
    percentile bootstrap ``level`` interval, the N (pred, target) pairs resampled with replacement
    ``n_resamples`` times (a resample with a constant side scores 0, as :func:`pearson` says).
    Fewer than 3 pairs: ``(r, nan, nan)``."""
    pred, target = np.asarray(pred, dtype=np.float64), np.asarray(target, dtype=np.float64)
    r = CORRELATIONS[kind](pred, target)
    if pred.size < 3:
        return r, float("nan"), float("nan")
    idx = np.random.default_rng(seed).integers(0, pred.size, size=(n_resamples, pred.size))
    lo, hi = np.quantile(_rowwise(kind, pred[idx], target[idx]), [(1 - level) / 2, 1 - (1 - level) / 2])
    return r, float(lo), float(hi)


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
