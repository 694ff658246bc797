"""The monotone map from a quality score to the opinion scale: the four-parameter logistic of the
VQEG's practice (``q = lo + (hi - lo) / (1 + exp(-(s - centre) / width))``, ``width > 0``), fitted by
least squares (``scipy.optimize.curve_fit``); a straight line where the logistic cannot be fitted
(fewer than five distinct scores, or no convergence). Increasing in the score either way, so it
changes no rank correlation, only the predicted opinion values (PLCC, errors)."""
from __future__ import annotations

import numpy as np

KINDS = ("logistic", "linear")


def _logistic(s: np.ndarray, lo: float, hi: float, centre: float, width: float) -> np.ndarray:
    z = np.clip((np.asarray(s, dtype=np.float64) - centre) / width, -60.0, 60.0)
    return lo + (hi - lo) / (1.0 + np.exp(-z))


def fit_opinion_map(score: np.ndarray, quality: np.ndarray) -> dict:
    """``{"kind", "params"}`` of the map of ``(N,)`` scores (higher = better) to ``(N,)`` opinions (higher = better)."""
    s, q = np.asarray(score, dtype=np.float64), np.asarray(quality, dtype=np.float64)
    var = s.var()
    slope = float(np.cov(s, q, bias=True)[0, 1] / var) if var > 0 else 0.0
    line = {"kind": "linear", "params": [float(q.mean() - slope * s.mean()), max(slope, 0.0)]}
    if len(np.unique(s)) < 5 or slope <= 0:
        return line
    from scipy.optimize import curve_fit

    spread = float(q.max() - q.min()) or 1.0
    p0 = [q.min(), q.max(), float(np.median(s)), float(s.std()) / 2.0]
    lower = [q.min() - spread, q.max() - spread / 2.0, s.min(), 1e-6 * float(np.ptp(s))]
    upper = [q.min() + spread / 2.0, q.max() + spread, s.max(), 10.0 * float(np.ptp(s))]
    try:
        params, _ = curve_fit(_logistic, s, q, p0=p0, bounds=(lower, upper), maxfev=5000)
    except (RuntimeError, ValueError):
        return line
    if not np.isfinite(params).all() or params[1] <= params[0]:
        return line
    return {"kind": "logistic", "params": [float(v) for v in params]}


def apply_opinion_map(opinion: dict, score: np.ndarray) -> np.ndarray:
    """``(N,)`` opinions of ``(N,)`` scores under a map of :func:`fit_opinion_map`."""
    p = opinion["params"]
    if opinion["kind"] == "logistic":
        return _logistic(score, *p)
    if opinion["kind"] == "linear":
        return p[0] + p[1] * np.asarray(score, dtype=np.float64)
    raise ValueError(f"unknown opinion map '{opinion['kind']}' (use one of {KINDS})")


def check_opinion_map(opinion) -> None:
    """ValueError unless ``opinion`` is a readable map: a known kind with its number of finite parameters."""
    n = {"logistic": 4, "linear": 2}
    kind = opinion.get("kind") if isinstance(opinion, dict) else None
    params = np.asarray(opinion.get("params", []) if kind else [], dtype=np.float64)
    if kind not in n or params.shape != (n[kind],) or not np.isfinite(params).all():
        raise ValueError(f"opinion map must be one of {KINDS} with finite parameters, got {opinion!r}")
