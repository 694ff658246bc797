"""Bootstrap confidence intervals of a mean and of a paired mean difference (SciPy's
``scipy.stats.bootstrap``, percentile method, seeded).

Small samples give wide intervals; fewer than 2 samples give NaN bounds (no interval).
"""
from __future__ import annotations

import numpy as np

N_RESAMPLES = 2000


def mean_ci(x, level: float = 0.95, seed: int = 0, n_resamples: int = N_RESAMPLES) -> tuple[float, float, float]:
    """``(mean, low, high)`` of ``(N,)`` samples: the mean and its bootstrap ``level`` interval."""
    from scipy.stats import bootstrap

    x = np.asarray(x, dtype=np.float64)
    if x.size == 0:
        return float("nan"), float("nan"), float("nan")
    m = float(x.mean())
    if x.size < 2 or np.ptp(x) == 0:
        return (m, float("nan"), float("nan")) if x.size < 2 else (m, m, m)
    res = bootstrap((x,), np.mean, confidence_level=level, n_resamples=n_resamples, method="percentile",
                    random_state=np.random.default_rng(seed), vectorized=True)
    return m, float(res.confidence_interval.low), float(res.confidence_interval.high)


def paired_difference_ci(a, b, level: float = 0.95, seed: int = 0,
                         n_resamples: int = N_RESAMPLES) -> tuple[float, float, float]:
    """``(mean(a - b), low, high)`` for paired ``(N,)`` samples (the same items scored two ways):
    samples are resampled as pairs, so the interval is that of the mean difference."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    if a.shape != b.shape:
        raise ValueError(f"paired samples differ in shape: {a.shape} vs {b.shape}")
    return mean_ci(a - b, level, seed, n_resamples)
