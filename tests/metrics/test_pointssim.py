"""PointSSIM (lit3d.metrics.pointssim): identities, invariances, monotonicity and a brute-force reference."""
from __future__ import annotations

import numpy as np
import pytest

from lit3d.metrics.pointssim import ESTIMATORS, POOLINGS, pointssim

VARIANTS = ("pointssim_geometry", "pointssim_normal", "pointssim_curvature", "pointssim_colour")


def surface(n: int = 2000, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Random points on a bumpy sphere of radius ~0.5, and smooth-plus-noise RGB colours in [0, 1]."""
    rng = np.random.default_rng(seed)
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    r = 0.5 * (1.0 + 0.08 * np.sin(5 * u[:, 0]) * np.cos(4 * u[:, 1]))
    points = u * r[:, None]
    colours = np.clip(0.5 + 0.3 * u[:, [0, 1, 2]] * np.array([1.0, -1.0, 0.5]) + rng.normal(0, 0.05, (n, 3)), 0, 1)
    return points, colours


def spacing(points: np.ndarray) -> float:
    from scipy.spatial import cKDTree

    return float(cKDTree(points).query(points, k=2)[0][:, 1].mean())


def test_identical_clouds_score_exactly_one():
    p, c = surface()
    s = pointssim(p, p.copy(), c, c.copy())
    assert set(s) == set(VARIANTS)
    assert all(v == 1.0 for v in s.values()), s
    normals = np.random.default_rng(1).normal(size=p.shape)
    s = pointssim(p, p, c, c, normals_a=normals, normals_b=normals)
    assert all(v == 1.0 for v in s.values()), s
    flipped = -2.0 * normals  # normals' sign and length do not matter
    assert pointssim(p, p, normals_a=normals, normals_b=flipped)["pointssim_normal"] == pytest.approx(1.0, abs=1e-12)


def test_point_order_does_not_matter():
    p, c = surface()
    rng = np.random.default_rng(8)
    q = p + rng.normal(0, 0.003, p.shape)
    perm = rng.permutation(len(p))
    want = pointssim(p, q, c, c)
    got = pointssim(p[perm], q, c[perm], c)
    assert got == pytest.approx(want, abs=1e-12)


def test_colour_score_only_with_both_colours():
    p, c = surface(500)
    assert set(pointssim(p, p)) == set(VARIANTS[:3])
    assert set(pointssim(p, p, c, None)) == set(VARIANTS[:3])
    assert set(pointssim(p, p, None, c)) == set(VARIANTS[:3])


def test_colour_change_moves_only_the_colour_score():
    p, c = surface()
    noisy = np.clip(c + np.random.default_rng(2).normal(0, 0.1, c.shape), 0, 1)
    s = pointssim(p, p, c, noisy)
    assert s["pointssim_geometry"] == s["pointssim_normal"] == s["pointssim_curvature"] == 1.0
    assert s["pointssim_colour"] < 0.5
    # A uniform brightness offset (BT.709 weights sum to 1: every luma + 51) keeps the local luma variance:
    # PointSSIM is structural and (with its default estimator) blind to it, but the "mean" estimator sees it.
    dark = 0.7 * c
    assert pointssim(p, p, dark, dark + 0.2)["pointssim_colour"] > 0.999
    assert pointssim(p, p, dark, dark + 0.2, estimator="mean")["pointssim_colour"] < 0.9


def test_displacement_lowers_geometry_monotonically():
    p, c = surface()
    h = spacing(p)
    rng = np.random.default_rng(3)
    noise = rng.normal(size=p.shape)
    scores = [pointssim(p, p + level * h * noise, c, c) for level in (0.05, 0.2, 0.5)]
    for name in ("pointssim_geometry", "pointssim_normal", "pointssim_curvature"):
        got = [s[name] for s in scores]
        assert 1.0 > got[0] > got[1] > got[2], (name, got)
    # The colours travel with their points: only neighbourhood changes move the luma variance.
    colour = [s["pointssim_colour"] for s in scores]
    assert all(0.8 < v <= 1.0 for v in colour), colour
    assert colour[0] > scores[0]["pointssim_geometry"]


def test_colour_noise_lowers_colour_monotonically():
    p, c = surface()
    noise = np.random.default_rng(4).normal(size=c.shape)
    got = [pointssim(p, p, c, np.clip(c + level * noise, 0, 1))["pointssim_colour"] for level in (0.02, 0.05, 0.15)]
    assert 1.0 > got[0] > got[1] > got[2], got


def test_symmetric_in_the_two_clouds():
    p, c = surface()
    rng = np.random.default_rng(5)
    q = p[rng.permutation(len(p))[:1700]] + rng.normal(0, 0.3 * spacing(p), (1700, 3))
    cq = rng.random((1700, 3))
    assert pointssim(p, q, c, cq) == pointssim(q, p, cq, c)
    options = {"estimator": "std", "pooling": "rms"}
    assert pointssim(p, q, c, cq, **options) == pointssim(q, p, cq, c, **options)


def test_single_thread_path_matches():
    p, c = surface(800)
    q = p + np.random.default_rng(6).normal(0, 0.01, p.shape)
    assert pointssim(p, q, c, c, workers=1) == pointssim(p, q, c, c)


def test_shared_trees_give_the_same_scores():
    """Trees built once (lit3d.metrics.pointcloud.kd_tree, as the feature table shares them with PCQM): every
    score bit-identical to PointSSIM building its own, duplicate points (ties) included; a tree of other
    points is refused."""
    from lit3d.metrics.pointcloud import kd_tree

    p, c = surface(900)
    p = np.round(p * 40) / 40  # a lattice: many equidistant neighbours, where tie-breaking would show
    q = p + np.random.default_rng(7).normal(0, 0.01, p.shape)
    for options in ({}, {"workers": 1}):
        assert pointssim(p, q, c, c, trees=(kd_tree(p), kd_tree(q)), **options) == pointssim(p, q, c, c, **options)
    with pytest.raises(ValueError, match="not a tree of those points"):
        pointssim(p, q, c, c, trees=(kd_tree(q), kd_tree(q)))


def test_bad_arguments():
    p, _ = surface(50)
    with pytest.raises(ValueError, match="estimator"):
        pointssim(p, p, estimator="qcd")
    with pytest.raises(ValueError, match="pooling"):
        pointssim(p, p, pooling="median")
    with pytest.raises(ValueError, match="points_b must be a finite"):
        pointssim(p, p[:, :2])
    with pytest.raises(ValueError, match="colours_a must have the shape"):
        pointssim(p, p, p[:10], p)
    with pytest.raises(ValueError, match="at least 3"):
        pointssim(p, p[:2])
    assert pointssim(p, p[:5])["pointssim_geometry"] <= 1.0  # k clamped to the smaller cloud


# --- brute-force reference: one point at a time, following the MATLAB code's steps literally ---------------------

def _brute_luma(rgb: np.ndarray) -> float:
    y = 255.0 * (0.2126 * rgb[0] + 0.7152 * rgb[1] + 0.0722 * rgb[2])
    return float(min(max(int(y + 0.5), 0), 255))  # uint8(round(y)) for y >= 0


def _brute_estimate(values: np.ndarray, estimator: str) -> float:
    v = [float(x) for x in values]
    n = len(v)
    mean = sum(v) / n
    med = float(np.median(v))
    var = sum((x - mean) ** 2 for x in v) / (n - 1)
    return {
        "variance": var, "std": var ** 0.5, "mean": mean, "median": med, "cov": var ** 0.5 / mean,
        "mean_ad": sum(abs(x - mean) for x in v) / n, "median_ad": float(np.median([abs(x - med) for x in v])),
    }[estimator]


def _brute_pool(sim: list[float], pooling: str) -> float:
    if pooling == "mean":
        return sum(sim) / len(sim)
    mse = sum(s * s for s in sim) / len(sim)
    return mse if pooling == "mse" else mse ** 0.5


def _brute_maps(points, colours, normals, k, estimator):
    n = len(points)
    neigh, dists = [], []
    for i in range(n):
        d = np.sqrt(np.sum((points - points[i]) ** 2, axis=1)).tolist()
        order = sorted(range(n), key=lambda j: d[j])[:k]
        neigh.append(order)
        dists.append([d[j] for j in order])
    curv, est_normals = [], []
    for i in range(n):
        nb = points[neigh[i]]
        centred = nb - nb.mean(0)
        w, v = np.linalg.eigh(centred.T @ centred)
        curv.append(w[0] / w.sum())
        est_normals.append(v[:, 0])
    normals = np.array(est_normals) if normals is None else normals
    maps = {"geometry": [], "normal": [], "curvature": [], "colour": []}
    for i in range(n):
        nbs = neigh[i]
        maps["geometry"].append(_brute_estimate(np.array(dists[i][1:]), estimator))
        ns = []
        for j in nbs[1:]:
            cosang = abs(normals[j] @ normals[i]) / (np.linalg.norm(normals[j]) * np.linalg.norm(normals[i]))
            ns.append(1 - 2 * np.arccos(min(cosang, 1.0)) / np.pi)
        maps["normal"].append(_brute_estimate(np.array(ns), estimator))
        maps["curvature"].append(_brute_estimate(np.array([curv[j] for j in nbs]), estimator))
        maps["colour"].append(_brute_estimate(np.array([_brute_luma(colours[j]) for j in nbs]), estimator))
    return maps


def brute_pointssim(a, b, ca, cb, na=None, nb=None, k=12, estimator="variance", pooling="mean"):
    fa, fb = _brute_maps(a, ca, na, k, estimator), _brute_maps(b, cb, nb, k, estimator)
    near_ba = [int(np.argmin(np.sum((a - x) ** 2, 1))) for x in b]  # A as reference: score of B
    near_ab = [int(np.argmin(np.sum((b - x) ** 2, 1))) for x in a]
    out = {}
    for name in fa:
        scores = []
        for f, f_ref, near in ((fb[name], fa[name], near_ba), (fa[name], fb[name], near_ab)):
            sim = []
            for i, fi in enumerate(f):
                r = f_ref[near[i]]
                sim.append(1 - abs(r - fi) / (max(abs(r), abs(fi)) + np.finfo(float).eps))
            scores.append(_brute_pool(sim, pooling))
        out[f"pointssim_{name}"] = min(scores)
    return out


def _small_pair(seed: int = 7):
    p, c = surface(200, seed)
    rng = np.random.default_rng(seed + 1)
    q = p[:180] + rng.normal(0, 0.01, (180, 3))
    cq = np.clip(c[:180] + rng.normal(0, 0.05, (180, 3)), 0, 1)
    return p, q, c, cq


def test_matches_brute_force_reference():
    p, q, c, cq = _small_pair()
    want = brute_pointssim(p, q, c, cq)
    got = pointssim(p, q, c, cq)
    assert set(got) == set(want)
    for name in want:
        assert got[name] == pytest.approx(want[name], abs=1e-6), name
    assert min(got.values()) < 0.95  # a real distortion, not a trivial 1 == 1


def test_matches_brute_force_with_given_normals_and_other_options():
    p, q, c, cq = _small_pair(11)
    rng = np.random.default_rng(12)
    na, nb = rng.normal(size=p.shape), rng.normal(size=q.shape)
    for estimator, pooling in (("std", "rms"), ("mean_ad", "mse"), ("median_ad", "mean"), ("mean", "mean"),
                               ("median", "mean"), ("cov", "mean"), ("variance", "mse")):
        assert estimator in ESTIMATORS and pooling in POOLINGS
        want = brute_pointssim(p, q, c, cq, na, nb, k=8, estimator=estimator, pooling=pooling)
        got = pointssim(p, q, c, cq, normals_a=na, normals_b=nb, k=8, estimator=estimator, pooling=pooling)
        for name in want:
            assert got[name] == pytest.approx(want[name], abs=1e-6), (estimator, pooling, name)
