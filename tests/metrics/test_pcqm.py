"""PCQM (lit3d.metrics.pcqm): zero for identical clouds, which features each distortion moves, monotonicity,
CIELAB against scikit-image, and the vectorised code against a brute-force per-point loop."""
from __future__ import annotations

import numpy as np
import pytest
from skimage.color import lab2rgb, rgb2lab

from lit3d.metrics import pcqm as pcqm_module
from lit3d.metrics.pcqm import FEATURES, WEIGHTS, pcqm, rgb_to_lab

CURV = ("curv_comparison", "curv_contrast", "curv_structure")
COLOUR = tuple(f for f in FEATURES if f not in CURV)


def bumpy_sphere(n: int = 3000, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """``(points (n, 3), colours (n, 3) in [0.2, 0.8])``: a bumpy unit sphere with smooth colours."""
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    theta, phi = np.arccos(d[:, 2]), np.arctan2(d[:, 1], d[:, 0])
    p = d * (1.0 + 0.1 * np.sin(3 * theta) * np.sin(4 * phi))[:, None]
    c = 0.5 + 0.3 * np.stack([np.sin(3 * p[:, 0]), np.cos(2 * p[:, 1]), np.sin(2 * p[:, 2] + 1)], 1)
    return p, c


def lab_colours(n: int, seed: int = 1) -> np.ndarray:
    """``(n, 3)`` in-gamut CIELAB colours (L in [40, 60], |a|, |b| <= 12)."""
    rng = np.random.default_rng(seed)
    return np.stack([rng.uniform(40, 60, n), rng.uniform(-12, 12, n), rng.uniform(-12, 12, n)], 1)


def to_rgb(lab: np.ndarray) -> np.ndarray:
    """sRGB of in-gamut CIELAB colours (asserted in gamut: ``lab2rgb`` would clip)."""
    rgb = lab2rgb(lab[None])[0]
    assert rgb.min() > 0.0 and rgb.max() < 1.0
    return rgb


@pytest.fixture(scope="module")
def sphere():
    return bumpy_sphere()


def test_identical_clouds_score_zero(sphere):
    p, c = sphere
    out = pcqm(p, p.copy(), c, c.copy())
    assert set(out) == {"pcqm"} | {f"pcqm_{f}" for f in FEATURES}
    for key, value in out.items():
        assert isinstance(value, float)
        assert abs(value) < 1e-12, key


def test_fusion_is_the_reference_weighted_sum(sphere):
    p, c = sphere
    rng = np.random.default_rng(3)
    out = pcqm(p, p + rng.normal(scale=0.005, size=p.shape), c, np.clip(c + rng.normal(scale=0.05, size=c.shape), 0, 1))
    assert WEIGHTS == {"curv_structure": 0.0057, "lightness_comparison": 0.9771, "lightness_structure": 0.0172}
    assert out["pcqm"] == pytest.approx(sum(w * out[f"pcqm_{f}"] for f, w in WEIGHTS.items()), rel=1e-12)
    assert all(out[f"pcqm_{f}"] > 0 for f in FEATURES)


def test_colour_shift_leaves_curvature_and_grows(sphere):
    p, c = sphere
    scores = []
    for shift in (0.02, 0.05, 0.1):
        out = pcqm(p, p, c, c + shift)  # colours stay in [0.2, 0.9]: no clipping
        for f in CURV:
            assert abs(out[f"pcqm_{f}"]) < 1e-12, f
        assert out["pcqm_lightness_comparison"] > 0
        scores.append(out)
    for key in ("pcqm", "pcqm_lightness_comparison"):
        assert scores[0][key] < scores[1][key] < scores[2][key], key


def test_lightness_only_changes_leave_chroma_and_hue(sphere):
    p, _ = sphere
    lab = lab_colours(len(p))
    shifted = lab + [8.0, 0.0, 0.0]
    out = pcqm(p, p, to_rgb(lab), to_rgb(shifted))
    assert out["pcqm_lightness_comparison"] > 1e-3
    # a uniform shift keeps every neighbourhood's lightness spread and structure
    for f in ("lightness_contrast", "lightness_structure", "chroma_comparison", "hue_comparison", *CURV):
        assert abs(out[f"pcqm_{f}"]) < 1e-9, f
    stretched = lab.copy()
    stretched[:, 0] = 50.0 + 1.8 * (lab[:, 0] - 50.0)
    out = pcqm(p, p, to_rgb(lab), to_rgb(stretched))
    assert out["pcqm_lightness_contrast"] > 1e-3
    for f in ("chroma_comparison", "hue_comparison", *CURV):
        assert abs(out[f"pcqm_{f}"]) < 1e-9, f


def test_chroma_and_hue_changes(sphere):
    p, _ = sphere
    lab = lab_colours(len(p))
    scaled = lab * [1.0, 1.5, 1.5]  # chroma x1.5, same hue angle
    out = pcqm(p, p, to_rgb(lab), to_rgb(scaled))
    assert out["pcqm_chroma_comparison"] > 1e-3
    assert abs(out["pcqm_hue_comparison"]) < 1e-9
    assert abs(out["pcqm_lightness_comparison"]) < 1e-9
    angle = np.deg2rad(30.0)
    rotated = lab.copy()
    rotated[:, 1] = np.cos(angle) * lab[:, 1] - np.sin(angle) * lab[:, 2]
    rotated[:, 2] = np.sin(angle) * lab[:, 1] + np.cos(angle) * lab[:, 2]
    out = pcqm(p, p, to_rgb(lab), to_rgb(rotated))  # same chroma, hue turned by 30 degrees
    assert out["pcqm_hue_comparison"] > 1e-3
    assert abs(out["pcqm_chroma_comparison"]) < 1e-9


def test_displacement_raises_curvature_features_monotonically(sphere):
    p, c = sphere
    rng = np.random.default_rng(5)
    noise = rng.normal(size=p.shape)
    outs = [pcqm(p, p + s * noise, c, c) for s in (0.002, 0.006, 0.02)]
    for f in CURV:
        values = [o[f"pcqm_{f}"] for o in outs]
        assert 0 < values[0] < values[1] < values[2], (f, values)
    scores = [o["pcqm"] for o in outs]
    assert 0 < scores[0] < scores[1] < scores[2]


def test_monotone_in_colour_noise(sphere):
    p, c = sphere
    noise = np.random.default_rng(6).normal(size=c.shape)
    outs = [pcqm(p, p, c, np.clip(c + s * noise, 0, 1)) for s in (0.01, 0.03, 0.1)]
    for key in ("pcqm", "pcqm_lightness_comparison", "pcqm_lightness_structure", "pcqm_chroma_comparison",
                "pcqm_hue_comparison"):
        values = [o[key] for o in outs]
        assert 0 < values[0] < values[1] < values[2], (key, values)


def test_radius_and_point_order_and_reference_direction(sphere):
    p, c = sphere
    rng = np.random.default_rng(7)
    q, cq = p + rng.normal(scale=0.01, size=p.shape), np.clip(c + rng.normal(scale=0.05, size=c.shape), 0, 1)
    base = pcqm(p, q, c, cq)
    perm_a, perm_b = rng.permutation(len(p)), rng.permutation(len(q))
    permuted = pcqm(p[perm_a], q[perm_b], c[perm_a], cq[perm_b])
    for key in base:
        assert permuted[key] == pytest.approx(base[key], rel=1e-9, abs=1e-12), key
    assert pcqm(p, q, c, cq, radius_factor=0.004) == base  # None -> the reference's 0.004
    assert pcqm(p, q, c, cq, radius_factor=0.05) != base
    assert pcqm(q, p, cq, c) != base  # one direction only: the first cloud is the reference


def test_subsampled_evaluation_is_deterministic(sphere, monkeypatch):
    p, c = sphere
    full = pcqm(p, p, c, c + 0.05)
    monkeypatch.setattr(pcqm_module, "POINT_BUDGET", 1000)
    sub = pcqm(p, p, c, c + 0.05)
    assert pcqm(p, p, c, c + 0.05) == sub
    assert sub["pcqm"] == pytest.approx(full["pcqm"], rel=0.2)
    assert all(abs(v) < 1e-12 for v in pcqm(p, p, c, c).values())


def test_shared_trees_give_the_same_result(sphere, monkeypatch):
    """Trees built once (lit3d.metrics.pointcloud.kd_tree, as the feature table shares them with PointSSIM):
    the same result, bit for bit, as PCQM building its own, also when it subsamples; a tree of other points is
    refused."""
    from lit3d.metrics.pointcloud import kd_tree

    p, c = sphere
    q = p + np.random.default_rng(8).normal(0, 0.005, p.shape)
    d = np.clip(c + np.random.default_rng(9).normal(0, 0.02, c.shape), 0, 1)
    assert pcqm(p, q, c, d, trees=(kd_tree(p), kd_tree(q))) == pcqm(p, q, c, d)
    monkeypatch.setattr(pcqm_module, "POINT_BUDGET", 500)
    assert pcqm(p, q, c, d, trees=(kd_tree(p), kd_tree(q)), workers=1) == pcqm(p, q, c, d, workers=1)
    with pytest.raises(ValueError, match="not a tree of those points"):
        pcqm(p, q, c, d, trees=(kd_tree(p), kd_tree(p[:-1])))


def test_rgb_to_lab_matches_skimage():
    rng = np.random.default_rng(8)
    rgb = np.concatenate([rng.uniform(size=(2000, 3)), np.eye(3), [[0, 0, 0], [1, 1, 1], [0.02, 0.03, 0.01]]])
    np.testing.assert_allclose(rgb_to_lab(rgb), rgb2lab(rgb[None])[0], atol=1e-9)


def test_bad_inputs():
    p, c = bumpy_sphere(50)
    with pytest.raises(ValueError):
        pcqm(p, p, c[:10], c)
    with pytest.raises(ValueError):
        pcqm(p[:, :2], p, c, c)
    with pytest.raises(ValueError):
        pcqm(p[:4], p, c[:4], c)
    with pytest.raises(ValueError):
        pcqm(p, p, c, c, radius_factor=0.0)


# ---- brute force: the reference's per-point loops (MEPP-team/PCQM main.cpp), with this module's
# documented neighbourhood rules, plain numpy and explicit neighbour lists


def _quadric(origin: np.ndarray, pts: np.ndarray) -> tuple[float, np.ndarray]:
    """``computeProjectionAndCurvature``: PCA frame (Eigen's column order), least-squares quadric, ``H``."""
    evals, evecs = np.linalg.eigh(np.cov(pts.T, bias=True))
    t1, t2, nrm = evecs[:, 2], evecs[:, 1], evecs[:, 0]
    rows, rhs = [], []
    for q in pts:
        v = q - origin
        x, y, z = v @ t1, v @ t2, v @ nrm
        rows.append([x * x, y * y, x * y, x, y, 1.0])
        rhs.append(z)
    coef = np.linalg.lstsq(np.array(rows), np.array(rhs), rcond=None)[0]
    fxx, fyy, fxy, fx, fy = 2 * coef[0], 2 * coef[1], coef[2], coef[3], coef[4]
    h = 0.5 * ((1 + fx * fx) * fyy + (1 + fy * fy) * fxx - 2 * fxy * fx * fy) / (1 + fx * fx + fy * fy) ** 1.5
    return h, origin + coef[5] * nrm


def _neighbours(cloud: np.ndarray, origin: np.ndarray, k_max: int, k_min: int, radius: float) -> list[int]:
    """Indices among the ``k_max`` nearest that lie within ``radius`` or rank below ``k_min``."""
    d = np.sqrt(((cloud - origin) ** 2).sum(1))
    order = np.argsort(d)[:k_max]
    return [int(j) for rank, j in enumerate(order) if d[j] <= radius or rank < k_min]


def brute_pcqm(a, b, ca, cb, radius_factor):
    """Every point of ``a`` evaluated one at a time: curvature/projection fits, then Gaussian statistics."""
    max_dim = float(np.max(a.max(0) - a.min(0)))
    radius = radius_factor * max_dim
    rs = pcqm_module.STATS_RADIUS_FACTOR * radius
    kp, kc = pcqm_module.K_PROJECTION, pcqm_module.K_MIN_CURVATURE
    ks, kmin = pcqm_module.K_MAX_STATS, pcqm_module.K_MIN_STATS
    n = len(a)
    curv_r, curv_d, nn, proj = np.zeros(n), np.zeros(n), np.zeros(n, int), np.zeros((n, 3))
    for i in range(n):
        o = a[i]
        curv_r[i] = abs(_quadric(o, a[_neighbours(a, o, kp, kc, radius)])[0]) * max_dim
        curv_d[i] = abs(_quadric(o, b[_neighbours(b, o, kp, kc, radius)])[0]) * max_dim
        knn = _neighbours(b, o, kp, kp, 0.0)
        nn[i] = knn[0]
        q = _quadric(o, b[knn])[1]
        proj[i] = q if np.linalg.norm(q - o) <= np.linalg.norm(b[nn[i]] - o) else b[nn[i]]
    lab_r, lab_d = rgb2lab(ca[None])[0], rgb2lab(cb[nn][None])[0]
    l_r, l_d = lab_r[:, 0], lab_d[:, 0]
    c_r, c_d = np.hypot(lab_r[:, 1], lab_r[:, 2]), np.hypot(lab_d[:, 1], lab_d[:, 2])
    hue = np.sqrt(np.maximum(((lab_r[:, 1:] - lab_d[:, 1:]) ** 2).sum(1) - (c_r - c_d) ** 2, 0))
    f = {name: [] for name in FEATURES}
    sim = {name: [] for name in ("l", "lc", "ls", "c", "h")}
    for i in range(n):
        nb = _neighbours(a, a[i], ks, kmin, rs)
        d_all = np.sort(np.linalg.norm(a - a[i], axis=1))
        sigma = max(rs, d_all[min(kmin, n) - 1]) / 2.0
        g = [1 / sigma / np.sqrt(2 * np.pi) * np.exp(-np.sum((a[j] - a[i]) ** 2) / 2 / sigma ** 2) for j in nb]
        gd = [1 / sigma / np.sqrt(2 * np.pi) * np.exp(-np.sum((proj[j] - proj[i]) ** 2) / 2 / sigma ** 2) for j in nb]
        sw, swd = sum(g), sum(gd)

        def stats(xr, xd):
            mr = sum(w * xr[j] for w, j in zip(g, nb)) / sw
            md = sum(w * xd[j] for w, j in zip(gd, nb)) / swd
            vr = sum(w * (xr[j] - mr) ** 2 for w, j in zip(g, nb)) / sw
            vd = sum(w * (xd[j] - md) ** 2 for w, j in zip(gd, nb)) / swd
            cov = sum(w * (xr[j] - mr) * (xd[j] - md) for w, j in zip(g, nb)) / sw
            return mr, md, np.sqrt(vr), np.sqrt(vd), cov

        mr, md, sr, sd, cov = stats(curv_r, curv_d)
        f["curv_comparison"].append(abs(mr - md) / (max(mr, md) + 1.0))
        f["curv_contrast"].append(abs(sr - sd) / (max(sr, sd) + 1.0))
        f["curv_structure"].append(min(abs(sr * sd - cov) / (sr * sd + 1.0), 1.0))
        mr, md, sr, sd, _ = stats(l_r, l_d)
        sim["l"].append(1 / (0.002 * (mr - md) ** 2 + 1))
        sim["lc"].append((2 * sr * sd + 0.1) / (sr ** 2 + sd ** 2 + 0.1))
        ur, ud = np.mean([l_r[j] for j in nb]), np.mean([l_d[j] for j in nb])
        vr, vd = np.mean([(l_r[j] - ur) ** 2 for j in nb]), np.mean([(l_d[j] - ud) ** 2 for j in nb])
        cov = np.mean([(l_r[j] - ur) * (l_d[j] - ud) for j in nb])
        sim["ls"].append((cov + 0.1) / (np.sqrt(vr) * np.sqrt(vd) + 0.1))
        mr, md = stats(c_r, c_d)[:2]
        sim["c"].append(1 / (0.002 * (mr - md) ** 2 + 1))
        sim["h"].append(1 / (0.008 * stats(hue, np.zeros(n))[0] ** 2 + 1))
    out = {name: float(np.mean(v)) for name, v in f.items() if v}
    for name, key in (("lightness_comparison", "l"), ("lightness_contrast", "lc"), ("lightness_structure", "ls"),
                      ("chroma_comparison", "c"), ("hue_comparison", "h")):
        out[name] = 1.0 - float(np.mean(sim[key]))
    out["pcqm"] = 0.0057 * out["curv_structure"] + 0.9771 * out["lightness_comparison"] + 0.0172 * out[
        "lightness_structure"]
    return out


@pytest.mark.parametrize("radius_factor", [0.08, 0.15, 0.25])
def test_matches_brute_force_loop(radius_factor):
    rng = np.random.default_rng(9)
    n = 200
    xy = rng.uniform(-1, 1, size=(n, 2))
    a = np.column_stack([xy, 0.3 * np.sin(2 * xy[:, 0]) * np.cos(3 * xy[:, 1])])
    b = np.concatenate([a[:150] + rng.normal(scale=0.02, size=(150, 3)),  # displaced part, a hole, outliers
                        rng.uniform(-1, 1, size=(40, 3)) * [1, 1, 0.2]])
    ca = rng.uniform(0.1, 0.9, size=(n, 3))
    cb = np.clip(np.concatenate([ca[:150] + rng.normal(scale=0.05, size=(150, 3)), rng.uniform(size=(40, 3))]), 0, 1)
    got = pcqm(a, b, ca, cb, radius_factor=radius_factor)
    want = brute_pcqm(a, b, ca, cb, radius_factor)
    for name in FEATURES:
        assert got[f"pcqm_{name}"] == pytest.approx(want[name], abs=1e-6), name
    assert got["pcqm"] == pytest.approx(want["pcqm"], abs=1e-6)
    assert 0 < got["pcqm"]
