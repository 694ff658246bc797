"""The colour-aware features of a coloured point-cloud pair: each piq measure and CIEDE2000 as the feature table
holds them equal the library called directly on the same renders; the MatCap colour style; the field's metrics
(PointSSIM, PCQM) in the table; the unlearned score keeps its colour styles."""
from __future__ import annotations

import numpy as np
import pytest
import torch
import torch.nn.functional as F
from tests.helpers.piq import piq_functions

from lit3d.features.config import UNLEARNED_COLOUR_STYLES, overall_score
from lit3d.features.point_table import PIQ_STYLES
from lit3d.features.table import FeatureConfig, feature_table
from lit3d.metrics.pcqm import pcqm
from lit3d.metrics.pointcloud import pointcloud_baselines
from lit3d.metrics.pointssim import pointssim
from lit3d.render.colour_styles import apply_colour_styles
from lit3d.render.gbuffer import RenderConfig
from lit3d.render.point_clouds import PointShape, load_points, local_frames
from lit3d.render.splat import point_frame, render_point_gbuffers
from lit3d.render.styles import apply_styles

SIZE = 96


def sphere(noise: float, seed: int = 0, n: int = 5000) -> PointShape:
    p = np.random.default_rng(0).normal(size=(n, 3))
    p /= np.linalg.norm(p, axis=1, keepdims=True)
    c = 0.5 + 0.4 * np.stack([np.sin(6 * p[:, 0]), np.cos(5 * p[:, 1]), np.sin(4 * p[:, 2])], 1)
    c = c + np.random.default_rng(seed).normal(0, noise, c.shape) if noise else c
    return PointShape(p, np.clip(c, 0, 1).astype(np.float32))


CFG = FeatureConfig(render=RenderConfig(size=SIZE, shadings=("flat",)), styles=("jade",), measures=("mask_ssim",),
                    workers=1)


def piq_direct(measure: str, a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """piq's own function on (V, 3, H, W) images, without lit3d's wrapper (reference first in lit3d, second in piq)."""
    module, name, kwargs = {"fsimc": ("fsim", "fsim", {"chromatic": True}), "vif": ("vif", "vif_p", {})}.get(
        measure, (measure, measure, {}))
    with piq_functions({measure: (module, name)}) as funcs:
        return funcs[measure](b, a, data_range=1.0, reduction="none", **kwargs)


@pytest.mark.skipif(__import__("importlib").util.find_spec("piq") is None, reason="piq not installed (bootstrap)")
def test_each_piq_measure_and_ciede2000_in_the_table_equal_the_library_on_the_same_renders():
    from lit3d.metrics.image.colour_measures import ciede2000

    ref, dist = sphere(0.0), sphere(0.15, 1)
    table = feature_table(ref, dist, CFG).features
    frame = point_frame(ref.points)
    ga = render_point_gbuffers(ref, CFG.render, frame=frame)["flat"]
    gb = render_point_gbuffers(dist, CFG.render, frame=frame)["flat"]
    ca = apply_colour_styles(ga.colour, ga.normals, ga.mask)
    cb = apply_colour_styles(gb.colour, gb.normals, gb.mask)
    style = PIQ_STYLES[0]
    down = CFG.fsim_downsample  # 96 px / 2 = 48 px >= VIF's 41
    a, b = F.avg_pool2d(ca[style], down), F.avg_pool2d(cb[style], down)
    for m in ("fsimc", "vif", "gmsd", "haarpsi", "mdsi", "vsi"):
        want = float(piq_direct(m, a, b).double().mean())
        assert table[f"{m}/{style}/flat"] == pytest.approx(want, rel=1e-5, abs=1e-6), m
    for s in ("albedo_rgb", "lit_rgb", "matcap_rgb"):
        want = float(ciede2000(ca[s], cb[s], ga.mask, gb.mask).double().mean())
        assert table[f"ciede2000/{s}/flat"] == pytest.approx(want, rel=1e-4), s


def test_matcap_colour_style_is_the_colour_under_the_matcap_light():
    g = render_point_gbuffers(sphere(0.0), RenderConfig(size=64, shadings=("flat",)))["flat"]
    out = apply_colour_styles(g.colour, g.normals, g.mask, ("matcap_rgb", "matcap_luma", "albedo_rgb"))
    light = apply_styles(g.normals, g.mask, ["clay_studio"], grey=True)[0]
    torch.testing.assert_close(out["matcap_rgb"], out["albedo_rgb"] * light)
    fg = g.mask.expand_as(out["matcap_rgb"])
    assert (out["matcap_rgb"][fg] <= out["albedo_rgb"][fg] + 1e-6).all() and out["matcap_rgb"][~fg].abs().max() == 0
    assert out["matcap_luma"].shape[1] == 1


def test_field_metrics_enter_the_table_and_the_unlearned_score_keeps_its_styles():
    ref, dist = sphere(0.0), sphere(0.15, 1)
    cfg = FeatureConfig(render=RenderConfig(size=48, shadings=("flat",)), styles=("jade",), measures=("mask_ssim",),
                        colour_measures=(), workers=1)
    f = feature_table(ref, dist, cfg).features
    frame_c, frame_s = point_frame(ref.points)
    a, b = (ref.points - frame_c) * frame_s, (dist.points - frame_c) * frame_s
    expect = {**pointssim(a, b, ref.colours, dist.colours), **pcqm(a, b, ref.colours, dist.colours)}
    for k, v in expect.items():
        assert f[k] == pytest.approx(v, rel=1e-9, abs=1e-12), k
    assert f["pointssim_colour"] < 1 and f["pcqm"] > 0 and f["pointssim_geometry"] == 1.0
    col = [v for k, v in f.items() if k.startswith("mask_ssim/") and k.split("/")[1] in UNLEARNED_COLOUR_STYLES]
    assert "mask_ssim/matcap_rgb/flat" in f and overall_score(f) == pytest.approx(np.mean(col))
    # an older table (without the new measures) is another cache key: never read back as this one
    assert cfg.key_dict() != FeatureConfig(render=cfg.render, styles=cfg.styles, measures=cfg.measures,
                                           colour_measures=(), point_measures=(), workers=1).key_dict()


@pytest.mark.parametrize("workers", [1, 2])
def test_point_metrics_in_the_table_equal_each_metric_computed_alone(tmp_path, workers):
    """The table computes PointSSIM and PCQM on one KD-tree per cloud, on worker threads beside the frames and
    renders (lit3d.features.point_table._point_metrics), the reference's frames while the distorted cloud loads
    (no cache folder) or after the cache look-up: each value bit-identical to the metric run alone, building its
    own trees, and to the D1/D2/Y-PSNR baselines from the clouds' own local frames. The clouds lie on a lattice
    (duplicate and equidistant points), where a different neighbour search would break ties differently."""
    def lattice(shape: PointShape) -> PointShape:
        return PointShape(np.round(shape.points * 24) / 24, shape.colours)

    ref, dist = lattice(sphere(0.0)), lattice(sphere(0.15, 1))
    cfg = FeatureConfig(render=RenderConfig(size=48, shadings=("flat",)), styles=("jade",), measures=("mask_ssim",),
                        colour_measures=(), workers=workers)
    pa, pb = load_points(ref), load_points(dist)  # the canonical point order the table works in
    frame_c, frame_s = point_frame(pa.points)
    a, b = (pa.points - frame_c) * frame_s, (pb.points - frame_c) * frame_s
    expect = {**pointcloud_baselines(a, b, local_frames(pa.points)["smooth"], local_frames(pb.points)["smooth"],
                                     pa.colours, pb.colours),
              **pointssim(a, b, pa.colours, pb.colours), **pcqm(a, b, pa.colours, pb.colours)}
    for cache_dir in (None, tmp_path):
        f = feature_table(ref, dist, cfg, cache_dir=cache_dir).features
        assert {k: f[k] for k in expect} == expect
