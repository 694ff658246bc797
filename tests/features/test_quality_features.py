"""Feature tables: names, caching, exact shortcuts, and monotonicity of the overall score."""
from __future__ import annotations

import json

import numpy as np
import pytest
import torch
import trimesh

from lit3d.metrics import image as im
from lit3d.features.table import FeatureConfig, feature_table, image_measures, overall_score
from lit3d.render.gbuffer import RenderConfig
from tests.helpers.paths import SHARED_DATA

SHARED_MESHES = SHARED_DATA / "meshes"
FAST = FeatureConfig(render=RenderConfig(size=96), measures=("mask_ssim",), mesh_measures=False)


def bumpy_sphere(subdiv: int = 4) -> trimesh.Trimesh:
    """Icosphere with smooth bumps (procedural test shape with detail to lose)."""
    s = trimesh.creation.icosphere(subdiv)
    v = s.vertices
    r = 1.0 + 0.08 * np.sin(5 * v[:, 0]) * np.sin(5 * v[:, 1]) * np.sin(5 * v[:, 2] + 1.0)
    return trimesh.Trimesh(v * r[:, None], s.faces, process=False)


def normal_noise(mesh: trimesh.Trimesh, sigma: float, seed: int = 0) -> trimesh.Trimesh:
    """Displace vertices along their normals by N(0, sigma) (sigma in unit-box units)."""
    m = mesh.copy()
    scale = float(np.ptp(m.vertices, 0).max())
    g = np.random.default_rng(seed)
    m.vertices = m.vertices + m.vertex_normals * (g.normal(0.0, sigma * scale, (len(m.vertices), 1)))
    return m


def taubin(mesh: trimesh.Trimesh, iterations: int) -> trimesh.Trimesh:
    """trimesh Taubin smoothing; its passes alternate shrink (lamb) and inflate (-nu) steps,
    so use even counts (an odd count ends on a bare shrink step). nu = 0.53 (stable)."""
    m = mesh.copy()
    trimesh.smoothing.filter_taubin(m, lamb=0.5, nu=0.53, iterations=iterations)
    return m


def _scores(ref, dists, cfg=FAST):
    return [feature_table(ref, d, cfg).overall_score() for d in dists]


def test_feature_names_and_values_full_table(tmp_path):
    ref = bumpy_sphere(3)
    dist = normal_noise(ref, 0.01)
    cfg = FeatureConfig(render=RenderConfig(size=64), styles=("ceramic_lightbulb", "toon"), n_samples=2000)
    t = feature_table(ref, dist, cfg, cache_dir=tmp_path)
    names = set(t.features)
    for m in ("mask_ssim", "mask_ssim_window", "mask_ssim_negative", "mask_ssim_merge", "ssim", "ms_ssim", "fsim",
              "mse", "rmse", "psnr", "canny", "sre"):
        for s in ("ceramic_lightbulb", "toon"):
            for sh in ("flat", "smooth"):
                assert f"{m}/{s}/{sh}" in names
    assert "chamfer" in names and "hausdorff" in names
    assert len(names) == 12 * 2 * 2 + 2
    assert all(np.isfinite(v) for v in t.features.values())
    assert 0 < t.features["mask_ssim_window/ceramic_lightbulb/flat"] < 1
    assert t.per_view["mask_ssim/toon/flat"].shape == (12,)
    # cache: JSON, keyed by content + config, read back identically
    files = list(tmp_path.glob("*.json"))
    assert len(files) == 1 and json.loads(files[0].read_text())["key"] == t.key
    t2 = feature_table(ref.copy(), dist.copy(), cfg, cache_dir=tmp_path)
    assert t2.cached and t2.features == pytest.approx(t.features)
    t3 = feature_table(ref, dist, FeatureConfig(render=RenderConfig(size=48), styles=("toon",), n_samples=2000),
                       cache_dir=tmp_path)
    assert not t3.cached and t3.key != t.key
    identical = feature_table(ref, ref.copy(), FeatureConfig(render=RenderConfig(size=64), styles=("toon",),
                                                             mesh_measures=False))
    assert identical.overall_score() == pytest.approx(1.0, abs=1e-6)


def test_crop_shortcut_equals_full_canvas():
    g = torch.Generator().manual_seed(0)
    a = torch.zeros(4, 1, 96, 96)
    b = torch.zeros(4, 1, 96, 96)
    ma = torch.zeros(4, 1, 96, 96, dtype=torch.bool)
    ma[..., 30:60, 25:70] = True
    mb = torch.zeros_like(ma)
    mb[..., 32:62, 25:66] = True
    a[ma] = torch.rand(int(ma.sum()), generator=g)
    b[mb] = torch.rand(int(mb.sum()), generator=g)
    want = ("mask_ssim", "mask_ssim_window", "mask_ssim_negative", "mask_ssim_merge", "ssim", "mse", "psnr",
            "sre", "canny")
    fast = image_measures(a, b, ma, mb, want, crop=True)
    slow = image_measures(a, b, ma, mb, want, crop=False)
    for k in want:
        assert torch.allclose(fast[k], slow[k], atol=1e-5), k
    assert torch.allclose(slow["ssim"], im.ssim(a, b), atol=1e-6)
    assert torch.allclose(slow["canny"], im.canny_diff(a, b), atol=1e-7)
    assert torch.allclose(slow["sre"], im.sre(a, b), atol=1e-4)


def test_overall_score_helper():
    f = {"mask_ssim/a/flat": 0.5, "mask_ssim/b/flat": 1.0, "ssim/a/flat": 0.0, "chamfer": 3.0}
    assert overall_score(f) == 0.75


def test_monotone_in_noise_strength_procedural():
    ref = bumpy_sphere(4)
    s = _scores(ref, [normal_noise(ref, sig) for sig in (0.001, 0.003, 0.008, 0.02)])
    assert all(x > y for x, y in zip(s, s[1:])), s


def test_monotone_in_taubin_iterations_procedural():
    ref = bumpy_sphere(4)
    s = _scores(ref, [taubin(ref, k) for k in (2, 6, 20, 60)])
    assert all(x > y for x, y in zip(s, s[1:])), s


@pytest.mark.skipif(not SHARED_MESHES.is_dir(), reason="../shared/data/meshes not present")
@pytest.mark.parametrize("name", ["bunny", "cow", "fandisk"])
def test_monotone_on_real_meshes(name):
    path = SHARED_MESHES / f"{name}.obj"
    if not path.is_file():
        pytest.skip(f"{path} missing")
    from lit3d.render.convert import to_mesh

    ref = to_mesh(path)
    noise = _scores(ref, [normal_noise(ref, sig) for sig in (0.001, 0.004, 0.012)])
    assert all(x > y for x, y in zip(noise, noise[1:])), noise
    smooth = _scores(ref, [taubin(ref, k) for k in (2, 8, 32)])
    assert all(x > y for x, y in zip(smooth, smooth[1:])), smooth


def test_canvas_study_mask_ssim_stable_plain_ssim_drifts(tmp_path):
    from studies.quality import canvas_study

    ref, dist = canvas_study.default_pair()
    rows = canvas_study.canvas_rows(ref, dist, canvases=(64, 128, 256), styles=("toon", "jade"), base_canvas=64)
    ms = [r["mask_ssim"] for r in rows]
    ss = [r["ssim"] for r in rows]
    assert max(ms) - min(ms) < 0.02
    assert ss[0] < ss[1] < ss[2] and ss[2] - ss[0] > 0.05
    assert "| 256 |" in canvas_study.markdown(rows)
    out = tmp_path / "t45.md"
    assert canvas_study.main(["--out", str(out), "--canvases", "64,128", "--styles", "toon"]) == 0
    assert out.read_text().startswith("# Canvas-size study")
