"""Shape-retrieval scores with the Princeton Shape Benchmark / SHREC definitions.

For every query q (a row of the distance matrix) the other n-1 items are ranked
by increasing distance; q itself is excluded. With C = size of q's class,
r = C - 1 relevant items remain, and with G_i = 1 when the i-th result is in
q's class:

    NN  = G_1
    FT  = (sum_{i<=r} G_i) / r                         (first tier)
    ST  = (sum_{i<=2r} G_i) / r                        (second tier)
    E   = 2 P R / (P + R) over the top k = min(32, n-1): P = h/k, R = h/r,
          which equals 2h / (r + k) with h = sum_{i<=k} G_i
    DCG = (G_1 + sum_{i>=2} G_i / log2 i) / (1 + sum_{j=2}^{r} 1 / log2 j)

Each score is averaged over queries; queries whose class has a single member
(r = 0) are skipped. Ties in distance are resolved by expectation: a block of
tied results shares its hits evenly over its positions, which is the mean of
the score over all orders of the tie (every score above is linear in the G_i).
"""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np

KEYS = ("nn", "ft", "st", "e", "dcg")
E_K = 32


def _expected_gains(d: np.ndarray, rel: np.ndarray) -> np.ndarray:
    """Expected G_i at each rank (ties share their hits evenly). ``d``, ``rel``: (n-1,)."""
    order = np.argsort(d, kind="stable")
    ds, rs = d[order], rel[order].astype(float)
    if len(ds) == 0:
        return rs
    group = np.cumsum(np.r_[True, ds[1:] != ds[:-1]]) - 1  # runs of equal distances
    return (np.bincount(group, weights=rs) / np.bincount(group))[group]


def retrieval_scores(dist, labels: Sequence) -> dict[str, float]:
    """``dist``: (n, n) distances (smaller = more similar; need not be symmetric),
    ``labels``: n class labels. Returns ``{"nn", "ft", "st", "e", "dcg", "n_queries"}``."""
    dist = np.asarray(dist, dtype=float)
    labels = np.asarray(list(labels))
    n = len(labels)
    if dist.shape != (n, n):
        raise ValueError(f"distance matrix of shape {dist.shape} for {n} labels")
    if np.isnan(dist).any():
        raise ValueError("distance matrix contains NaN")
    sums = dict.fromkeys(KEYS, 0.0)
    count = 0
    k = min(E_K, n - 1)
    disc = np.ones(max(n - 1, 0))
    disc[1:] = 1.0 / np.log2(np.arange(2, n))
    for q in range(n):
        others = np.arange(n) != q
        rel = labels[others] == labels[q]
        r = int(rel.sum())
        if r == 0:
            continue
        g = _expected_gains(dist[q, others], rel)
        sums["nn"] += g[0]
        sums["ft"] += g[:r].sum() / r
        sums["st"] += g[: 2 * r].sum() / r
        sums["e"] += 2.0 * g[:k].sum() / (r + k)
        sums["dcg"] += float((g * disc).sum() / disc[:r].sum())
        count += 1
    out = {k: (v / count if count else float("nan")) for k, v in sums.items()}
    out["n_queries"] = count
    return out


def chance_scores(labels: Sequence, n_trials: int = 100, seed: int = 0) -> dict[str, float]:
    """Mean scores of ``n_trials`` random symmetric distance matrices (the chance level)."""
    labels = list(labels)
    n = len(labels)
    rng = np.random.default_rng(seed)
    acc = dict.fromkeys(KEYS, 0.0)
    for _ in range(max(n_trials, 1)):
        a = rng.random((n, n))
        s = retrieval_scores((a + a.T) / 2, labels)
        for k in KEYS:
            acc[k] += s[k]
    out = {k: v / max(n_trials, 1) for k, v in acc.items()}
    out["n_queries"] = retrieval_scores(np.zeros((n, n)), labels)["n_queries"]
    return out


def expected_chance_scores(labels: Sequence) -> dict[str, float]:
    """Exact expectation under a uniformly random ranking: every G_i has mean r / (n-1)."""
    labels = np.asarray(list(labels))
    n = len(labels)
    return retrieval_scores(np.zeros((n, n)), labels)


def mask_iou(a, b) -> np.ndarray:
    """Mask IoU of every pair: ``(N, S, S)`` x ``(M, S, S)`` booleans -> ``(N, M)`` (0 for two empty masks)."""
    a, b = np.asarray(a, dtype=np.float32), np.asarray(b, dtype=np.float32)
    inter = np.einsum("nij,mij->nm", a, b)
    union = a.sum((1, 2))[:, None] + b.sum((1, 2))[None] - inter
    return inter / np.maximum(union, 1)


def mask_retrieval(masks, labels: Sequence) -> dict[str, float]:
    """:func:`retrieval_scores` of masks ``(N, S, S)`` (booleans) with distance 1 - mask IoU: no
    descriptor, no codebook, so no seed (the canonical task's validation retrieval and the pooled
    ``nn_by_mask`` / ``ft_by_mask`` rows)."""
    return retrieval_scores(1.0 - mask_iou(masks, masks), labels)
