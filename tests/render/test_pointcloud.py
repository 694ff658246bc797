"""Point clouds rendered as points: loading, PCA normals, splats, baselines, colour features."""
from __future__ import annotations

import zipfile

import numpy as np
import pytest
import torch

from lit3d.features.table import FeatureConfig, feature_table, overall_score
from lit3d.metrics.pointcloud import pointcloud_baselines, psnr_db
from lit3d.render.convert import ShapeError
from lit3d.render.gbuffer import RenderConfig
from lit3d.render.point_clouds import PointShape, is_point_source, load_points, local_frames, smallest_eigenvector


def sphere_points(n: int = 20000, seed: int = 0) -> np.ndarray:
    """Fibonacci sphere of radius 0.5 (quasi-uniform spacing)."""
    i = np.arange(n) + 0.5
    phi = np.arccos(1 - 2 * i / n)
    theta = np.pi * (1 + 5 ** 0.5) * i
    return 0.5 * np.stack([np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi), np.cos(phi)], 1)


def ply_text(points: np.ndarray, colours: np.ndarray, order=("red", "green", "blue"), faces: int | None = None) -> str:
    head = ["ply", "format ascii 1.0", f"element vertex {len(points)}", "property float x", "property float y",
            "property float z"] + [f"property uchar {c}" for c in order]
    if faces is not None:
        head += [f"element face {faces}", "property list uint8 int32 vertex_index"]
    head.append("end_header")
    idx = {"red": 0, "green": 1, "blue": 2}
    body = [" ".join([f"{v:.6f}" for v in p] + [str(int(c[idx[o]])) for o in order]) for p, c in zip(points, colours)]
    return "\n".join(head + body) + "\n"


def write_zip(path, text: str, inner: str = "cloud.ply") -> None:
    with zipfile.ZipFile(path, "w") as z:
        z.writestr(inner, text)


# ------------------------------------------------------------------ baselines vs brute force
def brute(a, b, na, nb, ca, cb):
    d = ((b[:, None, :] - a[None]) ** 2).sum(-1)  # (M, N)
    iba, iab = d.argmin(1), d.argmin(0)
    e_ba, e_ab = d.min(1), d.min(0)
    d1 = max(e_ba.mean(), e_ab.mean())
    p2 = max(((((b - a[iba]) * na[iba]).sum(1)) ** 2).mean(), ((((a - b[iab]) * nb[iab]).sum(1)) ** 2).mean())
    w = np.array([0.2126, 0.7152, 0.0722])
    y = max(((cb @ w - (ca @ w)[iba]) ** 2).mean(), ((ca @ w - (cb @ w)[iab]) ** 2).mean())
    return d1, p2, y, max(np.sqrt(e_ba).max(), np.sqrt(e_ab).max())


def test_baselines_match_brute_force():
    rng = np.random.default_rng(1)
    a, b = rng.random((120, 3)), rng.random((90, 3))
    na = rng.normal(size=(120, 3))
    na /= np.linalg.norm(na, axis=1, keepdims=True)
    nb = rng.normal(size=(90, 3))
    nb /= np.linalg.norm(nb, axis=1, keepdims=True)
    ca, cb = rng.random((120, 3)), rng.random((90, 3))
    out = pointcloud_baselines(a, b, na, nb, ca, cb)
    d1, d2, y, h = brute(a, b, na, nb, ca, cb)
    peak = np.linalg.norm(a.max(0) - a.min(0))
    assert out["d1_mse"] == pytest.approx(d1, rel=1e-9)
    assert out["d1_psnr"] == pytest.approx(10 * np.log10(peak ** 2 / d1), rel=1e-9)
    assert out["d2_mse"] == pytest.approx(d2, rel=1e-9)
    assert out["d2_psnr"] == pytest.approx(10 * np.log10(peak ** 2 / d2), rel=1e-9)
    assert out["y_mse"] == pytest.approx(y, rel=1e-9)
    assert out["y_psnr"] == pytest.approx(10 * np.log10(1 / y), rel=1e-9)
    assert out["hausdorff"] == pytest.approx(h, rel=1e-9)
    same = pointcloud_baselines(a, a, na, na, ca, ca)
    assert same["d1_psnr"] == same["d2_psnr"] == same["y_psnr"] == psnr_db(0.0, 1.0) == 100.0


def test_smallest_eigenvector_matches_eigh():
    rng = np.random.default_rng(0)
    x = rng.normal(size=(500, 8, 3)) * np.array([1.0, 0.4, 0.05])
    x = x @ np.linalg.qr(rng.normal(size=(3, 3)))[0]
    cov = np.matmul(x.transpose(0, 2, 1), x)
    ref = np.linalg.eigh(cov)[1][:, :, 0]
    got = smallest_eigenvector(cov)
    assert np.abs(np.abs((got * ref).sum(1)) - 1).max() < 1e-5
    assert np.allclose(smallest_eigenvector(np.eye(3)[None] * 2.0), [[0, 0, 1]])


def test_pca_normals_of_sphere_are_radial():
    p = sphere_points(4000)
    lf = local_frames(p)
    radial = p / np.linalg.norm(p, axis=1, keepdims=True)
    for k in ("flat", "smooth"):
        assert np.median(np.abs((lf[k] * radial).sum(1))) > 0.99
    assert lf["spacing"].shape == (4000,) and np.all(lf["spacing"] > 0)


# ------------------------------------------------------------------ loading and bad files
def test_load_zipped_ascii_ply_any_colour_order(tmp_path):
    rng = np.random.default_rng(2)
    p, c = rng.random((50, 3)), rng.integers(0, 256, (50, 3))
    write_zip(tmp_path / "a.zip", ply_text(p, c, order=("green", "blue", "red"), faces=0))
    assert is_point_source(tmp_path / "a.zip")
    ps = load_points(tmp_path / "a.zip")
    order = np.lexsort((p[:, 2], p[:, 1], p[:, 0]))  # points come back in canonical (sorted) order
    assert np.allclose(ps.points, p[order], atol=1e-6)
    assert np.allclose(ps.colours * 255, c[order], atol=1e-3)
    (tmp_path / "b.ply").write_text(ply_text(p, c))
    assert is_point_source(tmp_path / "b.ply")
    assert np.allclose(load_points(tmp_path / "b.ply").points, p[order], atol=1e-6)


@pytest.mark.parametrize("case,expect", [
    ("nozip", "not a readable zip"), ("twoply", "expected exactly one"), ("faces", "it is a mesh"),
    ("short", "header declares 50 vertices"), ("nan", "NaN"), ("magic", "not a PLY file"), ("empty", "empty file"),
])
def test_bad_point_files_one_line(tmp_path, case, expect):
    rng = np.random.default_rng(3)
    p, c = rng.random((50, 3)), rng.integers(0, 256, (50, 3))
    path = tmp_path / "bad.zip"
    if case == "nozip":
        path.write_bytes(b"not a zip at all")
    elif case == "twoply":
        with zipfile.ZipFile(path, "w") as z:
            z.writestr("a.ply", ply_text(p, c))
            z.writestr("b.ply", ply_text(p, c))
    elif case == "faces":
        write_zip(path, ply_text(p, c, faces=3))
    elif case == "short":
        write_zip(path, ply_text(p, c).rsplit("\n", 6)[0] + "\n")
    elif case == "nan":
        p[3, 1] = np.nan
        write_zip(path, ply_text(p, c))
    elif case == "magic":
        write_zip(path, "hello\nend_header\n1 2 3\n")
    else:
        path.write_bytes(b"")
    with pytest.raises(ShapeError) as err:
        load_points(path)
    msg = str(err.value)
    assert str(path) in msg and expect in msg and "\n" not in msg


# ------------------------------------------------------------------ splats and features
def test_splat_matches_mesh_render_of_sphere():
    trimesh = pytest.importorskip("trimesh")
    from lit3d.render.gbuffer import render_gbuffers
    from lit3d.render.splat import render_point_gbuffers

    cfg = RenderConfig(size=64, shadings=("smooth",))
    mesh = trimesh.creation.icosphere(subdivisions=4, radius=0.5)
    gm = render_gbuffers(mesh, cfg)["smooth"]
    pts = PointShape(sphere_points(20000))
    gp = render_point_gbuffers(pts, cfg)["smooth"]
    inter = (gm.mask & gp.mask).sum().item()
    union = (gm.mask | gp.mask).sum().item()
    assert inter / union > 0.93
    both = (gm.mask & gp.mask).expand(-1, 3, -1, -1)
    dots = (gm.normals * gp.normals).sum(1, keepdim=True)[(gm.mask & gp.mask)]
    assert dots.median() > 0.98 and both.any()


def test_zbuffer_equals_a_bounds_tested_scatter_per_splat_pixel():
    """lit3d.render.splat.nearest_splats (a margin around each view, a sink for discs that cannot reach the
    image, the points grouped by radius) against the plain form: every splat pixel of every point scattered
    with a bounds test. Every radius 0..MAX_RADIUS_PX, centres inside, on the border and far outside the image,
    equal keys (ties): the same z-buffer, bit for bit."""
    from lit3d.render.splat import EMPTY, MAX_RADIUS_PX, _disc, nearest_splats

    g = torch.Generator().manual_seed(0)
    v, n, s = 3, 400, 64
    row = torch.randint(-30, s + 30, (v, n), generator=g)
    col = torch.randint(-30, s + 30, (v, n), generator=g)
    key = torch.randint(0, 50, (v, n), generator=g) * n + torch.arange(n)  # quantised depth x N + index
    radius = torch.randint(0, MAX_RADIUS_PX + 1, (n,), generator=g)
    expect = torch.full((v, s * s), EMPTY, dtype=torch.int64)
    for r in range(MAX_RADIUS_PX + 1):
        sel = radius == r
        for dy, dx in _disc(r).tolist():
            y, x = row[:, sel] + dy, col[:, sel] + dx
            ok = (y >= 0) & (y < s) & (x >= 0) & (x < s)
            for j in range(v):
                expect[j].scatter_reduce_(0, (y[j] * s + x[j])[ok[j]], key[j, sel][ok[j]], "amin")
    got = nearest_splats(row, col, key, radius, s)
    assert torch.equal(got, expect) and (got == EMPTY).any() and (got != EMPTY).any()


def test_local_frames_column_form_is_the_row_form_bit_for_bit():
    """local_frames gathers the neighbour offsets one coordinate at a time (lit3d.render.point_clouds.column_covariance);
    the normals are bit-identical to those of the (N, k, 3) offsets' covariance (its mean over the middle axis
    and row-wise products), on a lattice with duplicate points and on points of very different scales."""
    from scipy.spatial import cKDTree

    rng = np.random.default_rng(4)
    clouds = [np.round(sphere_points(3000) * 30) / 30,
              rng.normal(size=(3000, 3)) * np.exp(rng.normal(size=(3000, 1)) * 2)]
    for p in clouds:
        _, idx = cKDTree(p).query(p, k=16)
        p32 = (p - p.mean(0)).astype(np.float32)
        nb = p32[idx] - p32[:, None, :]
        lf = local_frames(p)
        for name, kk in (("flat", 8), ("smooth", 16)):
            x = nb[:, :kk]
            m = x.mean(1, dtype=np.float64)
            cov = np.empty((len(p), 3, 3))
            for i in range(3):
                for j in range(3):
                    xi, xj = np.ascontiguousarray(x[..., i]), np.ascontiguousarray(x[..., j])
                    cov[:, i, j] = np.einsum("nk,nk->n", xi, xj, dtype=np.float64) - kk * m[:, i] * m[:, j]
            assert np.array_equal(lf[name], smallest_eigenvector(cov)), name


def coloured_sphere(noise: float, seed: int = 0) -> PointShape:
    p = sphere_points(6000)
    c = 0.5 + 0.4 * np.stack([np.sin(6 * p[:, 0]), np.cos(5 * p[:, 1]), np.sin(4 * p[:, 2])], 1)
    c = c + np.random.default_rng(seed).normal(0, noise, c.shape) if noise else c
    return PointShape(p, np.clip(c, 0, 1).astype(np.float32))


FAST = FeatureConfig(render=RenderConfig(size=48, shadings=("flat",)), styles=("ceramic_lightbulb", "metal_lead"),
                     measures=("mask_ssim", "ssim", "psnr"), colour_measures=("ciede2000",), point_measures=(), workers=1)


def test_colour_noise_only_changes_colour_features_monotonically():
    ref = coloured_sphere(0.0)
    same = feature_table(ref, coloured_sphere(0.0), FAST).features
    assert all(v == pytest.approx(1.0) for k, v in same.items() if k.startswith("mask_ssim/"))
    assert {"mask_ssim/albedo_rgb/flat", "psnr/lit_rgb/flat", "mask_ssim/lit_luma/flat", "d1_psnr",
            "d2_psnr", "y_psnr", "hausdorff", "chamfer"} <= set(same)
    scores, ypsnr = [], []
    for noise in (0.03, 0.1, 0.3):
        f = feature_table(ref, coloured_sphere(noise, 1), FAST).features
        assert f["mask_ssim/ceramic_lightbulb/flat"] == pytest.approx(1.0)  # geometry untouched
        assert f["d1_psnr"] == 100.0
        assert f["mask_ssim/albedo_rgb/flat"] < 1.0
        scores.append(overall_score(f))
        ypsnr.append(f["y_psnr"])
    assert scores[0] > scores[1] > scores[2] and scores[0] < 1.0
    assert ypsnr[0] > ypsnr[1] > ypsnr[2]
    geo = []  # the colour-based overall score still sees geometry: same colours, noisier positions
    for sigma in (0.0, 0.004, 0.012):
        q = ref.points + np.random.default_rng(5).normal(0, sigma, ref.points.shape) if sigma else ref.points
        geo.append(overall_score(feature_table(ref, PointShape(q, ref.colours), FAST).features))
    assert geo[0] == pytest.approx(1.0) and geo[0] > geo[1] > geo[2]


def test_colourless_points_have_no_colour_features_and_geometry_noise_is_monotone():
    p = sphere_points(6000)
    ref = PointShape(p)
    scores = []
    for sigma in (0.0, 0.004, 0.012):
        q = p + np.random.default_rng(5).normal(0, sigma, p.shape) if sigma else p
        f = feature_table(ref, PointShape(q), FAST).features
        assert not any("albedo" in k or "lit_" in k or k.startswith("y_") for k in f)
        scores.append(overall_score(f))
    assert scores[0] == pytest.approx(1.0) and scores[0] > scores[1] > scores[2]


def test_points_feature_table_cache(tmp_path):
    ref, dist = coloured_sphere(0.0), coloured_sphere(0.1, 2)
    a = feature_table(ref, dist, FAST, cache_dir=tmp_path)
    b = feature_table(ref, dist, FAST, cache_dir=tmp_path)
    assert not a.cached and b.cached and a.features == pytest.approx(b.features)
    assert torch.get_num_threads() >= 1


def test_xyz_array_is_point_source():
    assert is_point_source(np.zeros((10, 3))) and is_point_source(np.zeros((10, 6)))
    assert not is_point_source(np.zeros((4, 4, 4)))


def test_point_order_does_not_change_the_renders():
    """A voxel-lattice cloud and the same points shuffled: identical features (canonical order)."""
    g = np.mgrid[0:40, 0:40, 0:40].reshape(3, -1).T.astype(float)
    shell = g[np.abs(np.linalg.norm(g - 19.5, axis=1) - 15) < 0.7]
    col = (shell / 40.0).astype(np.float32)
    perm = np.random.default_rng(0).permutation(len(shell))
    f = feature_table(PointShape(shell, col), PointShape(shell[perm], col[perm]), FAST).features
    assert all(v == pytest.approx(1.0) for k, v in f.items() if k.startswith("mask_ssim/"))


def test_cached_frames_is_thread_safe(monkeypatch):
    """Many threads asking for a few clouds at once: each cloud's frames computed once, every
    caller gets that one result, and the memo keeps its bound (lit3d.features.point_table._FRAMES)."""
    import threading
    import time

    from lit3d.features import point_table as pf

    calls: dict[int, int] = {}

    def slow_frames(p, workers=-1):
        calls[len(p)] = calls.get(len(p), 0) + 1
        time.sleep(0.02)  # let the other threads reach the check while this one computes
        return {"n": np.full(1, len(p))}

    monkeypatch.setattr(pf, "local_frames", slow_frames)
    monkeypatch.setattr(pf, "_FRAMES", type(pf._FRAMES)())
    shapes = {f"k{n}": PointShape(np.zeros((n, 3))) for n in range(1, 4)}
    got, start = [], threading.Barrier(12)

    def ask(key):
        start.wait()
        got.append((key, pf.cached_frames(shapes[key], key)))

    threads = [threading.Thread(target=ask, args=(f"k{1 + i % 3}",)) for i in range(12)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert calls == {1: 1, 2: 1, 3: 1} and len(got) == 12
    assert all(lf is pf._FRAMES[key] and int(lf["n"][0]) == int(key[1:]) for key, lf in got)
    assert not pf._FRAMES_PENDING and len(pf._FRAMES) <= pf._FRAMES_KEEP
