"""Quality feature table vs per-style lit rendering; the worker pool; batched Mask-SSIM vs scikit-image.

Rows:
1. Full feature table (30 styles x 2 shadings x 12 views, every image measure, Chamfer and
   Hausdorff) of one ~30k-face mesh pair at 256^2 with the default configuration, against
   rendering every style as a separate lit pyrender pass (the thesis's approach, there with
   Blender: 2 meshes x 2 shadings x 30 styles x 12 views = 1440 renders). The baseline is timed
   on 2 styles (96 renders) and multiplied by 15 (linear in the number of styles), and counts
   rendering only (no measures), which favours the baseline.
2. The same table with the default worker pool (``FeatureConfig.workers=0``: one thread per
   core, one intra-op thread each) against ``workers=1`` (views one after another, one thread).
3. Mask-SSIM (all four variants + SSIM from one map) for 360 image pairs at 256^2, batched
   torch vs scikit-image ``structural_similarity(full=True)`` + masked mean per image (timed on
   24 pairs, scaled to 360); both with one thread.
4. On a CUDA machine: the feature table at 512^2 with the measures on the GPU.
5. (:func:`point_rows`) Full feature table of a pair of coloured 300k-point clouds written as zipped
   ASCII PLY (loading, PCA normals, splatting, 34 styles incl. colour, all measures, D1/D2/Y-PSNR
   baselines) against the previous path for point clouds: meshing both clouds (``to_mesh``: 96^3
   occupancy grid + marching cubes) and the mesh table (colour ignored).
"""
from __future__ import annotations

import os
import time

import numpy as np
import torch

from benchmarks.common import GPU_CMD, default_threads, median_time, num_threads, row, target_note

CMD = "make bench"
TABLE_TARGET_S, TABLE_TARGET_RATIO = 10.0, 10.0
BASELINE_STYLES = 2


def _pair(faces_major: int = 192, faces_minor: int = 80):
    import trimesh

    ref = trimesh.creation.torus(0.5, 0.2, major_sections=faces_major, minor_sections=faces_minor)
    g = np.random.default_rng(0)
    v = ref.vertices
    bumps = 0.01 * np.sin(12 * np.arctan2(v[:, 1], v[:, 0]))[:, None]
    ref = trimesh.Trimesh(v + ref.vertex_normals * bumps, ref.faces, process=False)
    dist = ref.copy()
    dist.vertices = dist.vertices + dist.vertex_normals * g.normal(0, 0.004, (len(v), 1))
    return ref, dist


def lit_render_per_style(meshes, size: int, n_styles: int, shadings=("flat", "smooth")) -> float:
    """Seconds to render ``n_styles`` lit passes per mesh x shading x 12 views (pyrender)."""
    from lit3d.render.convert import normalise
    from lit3d.render.egl import import_pyrender, offscreen_renderer
    from lit3d.render.dodecahedron import camera_poses

    pyrender = import_pyrender()
    r = offscreen_renderer(size, size)
    poses = camera_poses(3.0)
    t0 = time.perf_counter()
    for m in meshes:
        m = normalise(m)
        for shading in shadings:
            for s in range(n_styles):
                scene = pyrender.Scene(bg_color=[0, 0, 0, 0], ambient_light=[0.1, 0.1, 0.1])
                mat = pyrender.MetallicRoughnessMaterial(baseColorFactor=[0.3 + 0.02 * s, 0.5, 0.7, 1.0],
                                                         metallicFactor=0.2, roughnessFactor=0.5)
                scene.add(pyrender.Mesh.from_trimesh(m, material=mat, smooth=shading == "smooth"))
                cam = scene.add(pyrender.OrthographicCamera(0.9, 0.9, znear=0.05, zfar=5.0), pose=poses[0])
                light = scene.add(pyrender.DirectionalLight(intensity=3.0), pose=poses[0])
                for p in poses:
                    scene.set_pose(cam, p)
                    scene.set_pose(light, p)
                    r.render(scene)
    return time.perf_counter() - t0


def _mask_ssim_rows(size: int = 256, n: int = 360, n_ref: int = 24) -> dict:
    from skimage.metrics import structural_similarity

    from lit3d.metrics.image import mask_ssim_all

    g = torch.Generator().manual_seed(0)
    yy, xx = torch.meshgrid(torch.linspace(-1, 1, size), torch.linspace(-1, 1, size), indexing="ij")
    disc = (xx**2 + yy**2 < 0.6).expand(n, 1, size, size)
    a = torch.rand(n, 1, size, size, generator=g) * disc
    b = (a + 0.05 * torch.randn(n, 1, size, size, generator=g)).clamp(0, 1) * disc
    ours = median_time(lambda: mask_ssim_all(a, b, disc, disc), repeats=3)
    an, bn, mn = a.numpy(), b.numpy(), disc.numpy()
    vals = []

    def ref():
        vals.clear()
        for i in range(n_ref):
            _, s = structural_similarity(an[i, 0], bn[i, 0], gaussian_weights=True, sigma=1.5,
                                         use_sample_covariance=False, data_range=1.0, full=True)
            m = mn[i, 0]
            vals.append((s * m).sum() / m.sum())
    base = median_time(ref, repeats=3) * n / n_ref
    same = mask_ssim_all(a[:n_ref], b[:n_ref], disc[:n_ref], disc[:n_ref])["mask_ssim"].double().numpy()
    if not np.allclose(same, np.asarray(vals), atol=1e-5):  # the two sides must compute the same thing
        raise AssertionError(f"Mask-SSIM differs from scikit-image: {np.abs(same - np.asarray(vals)).max()}")
    return {"ours": ours, "base": base, "n": n, "size": size, "run": lambda: mask_ssim_all(a, b, disc, disc)}


def run() -> list[dict]:
    from lit3d.features.table import FeatureConfig, feature_table
    from lit3d.render.gbuffer import RenderConfig

    rows = []
    ref, dist = _pair()
    nf = len(ref.faces)
    cfg = FeatureConfig(render=RenderConfig(size=256))
    workers = cfg.workers or default_threads()
    feature_table(ref, dist, FeatureConfig(render=RenderConfig(size=64), styles=("toon",)))  # warm EGL/LUTs
    with num_threads(default_threads()):
        ours = median_time(lambda: feature_table(ref, dist, cfg), repeats=3, warmup=1)
        seq = median_time(lambda: feature_table(ref, dist, FeatureConfig(render=RenderConfig(size=256), workers=1)),
                          repeats=3, warmup=0)
        lit = median_time(lambda: lit_render_per_style([ref, dist], 256, BASELINE_STYLES), repeats=3, warmup=1)
    base = lit * 30 / BASELINE_STYLES
    n_feat = len(feature_table(ref, dist, cfg).features)
    rows.append(row(f"quality feature table, {nf}-face pair, 30 styles x 2 shadings x 12 views, 256^2, all measures "
                    f"({n_feat} features)", CMD, ours, base, baseline_name="1440 lit pyrender passes (render only)",
                    threads=workers,
                    note=f"{target_note('time', ours, TABLE_TARGET_S, False, ' s')}; "
                         f"{target_note('speed-up', base / ours, TABLE_TARGET_RATIO, True, 'x')}; default config: "
                         f"{workers} worker threads x 1 intra-op thread; baseline timed on {BASELINE_STYLES} styles "
                         f"({BASELINE_STYLES * 48} renders, {lit:.2f} s) and extrapolated linearly to 30 styles, "
                         "rendering only (no measures): favours the baseline"))
    rows.append(row(f"quality feature table worker pool: {workers} view workers vs views in sequence "
                    "(workers=1, 1 thread), same table", CMD, ours, seq, baseline_name="workers=1", threads=workers,
                    note=f"does the thread pool help? speed-up {seq / ours:.2f}x on {os.cpu_count()} cores "
                         "(it can only use cores other jobs leave free; see the load in the machine column)"))
    with num_threads(1):
        ms = _mask_ssim_rows()
    with num_threads(default_threads()):
        ms2 = median_time(lambda: ms["run"](), repeats=2, warmup=1)
    rows.append(row(f"Mask-SSIM (4 variants + SSIM), {ms['n']} pairs at {ms['size']}^2, batched torch", CMD,
                    ms["ours"], ms["base"], baseline_name="scikit-image per image", threads=1,
                    note=f"{ms['n'] / ms['ours']:.0f} pairs/s vs {ms['n'] / ms['base']:.0f} pairs/s; both 1 thread; "
                         f"scikit-image timed on 24 pairs and scaled to {ms['n']}; ours with {default_threads()} "
                         f"threads: {ms2:.2f} s"))
    return rows + gpu_rows(ref, dist) + point_rows()


def gpu_rows(ref=None, dist=None) -> list[dict]:
    """The feature table at 512^2 with the measures on the GPU, against the same table with the measures
    on the CPU in the same run (``python -m benchmarks.run --gpu``); a placeholder row without CUDA."""
    from lit3d.features.table import FeatureConfig, feature_table
    from lit3d.render.gbuffer import RenderConfig

    if ref is None:
        ref, dist = _pair()
    name = f"quality feature table, {len(ref.faces)}-face pair, 30 styles x 2 shadings x 12 views, 512^2, measures on GPU"
    if not torch.cuda.is_available():
        return [row(name, GPU_CMD, None, None, note="not measured: no CUDA device on this machine")]
    cfg512 = FeatureConfig(render=RenderConfig(size=512))
    with num_threads(default_threads()):
        on_gpu = feature_table(ref, dist, cfg512, device="cuda")
        gpu = median_time(lambda: feature_table(ref, dist, cfg512, device="cuda"), repeats=3, warmup=0)
        on_cpu = feature_table(ref, dist, cfg512)
        cpu = median_time(lambda: feature_table(ref, dist, cfg512), repeats=2, warmup=0)
    shared = sorted(set(on_gpu.features) & set(on_cpu.features))
    worst = float(np.nanmax([abs(on_gpu.features[k] - on_cpu.features[k]) for k in shared]))
    return [row(name, GPU_CMD, gpu, cpu, baseline_name="measures on the CPU", device="cuda",
                note=f"per pair, rendering included (pyrender, EGL); {len(shared)} features, largest GPU-CPU "
                     f"difference {worst:.2g}; {target_note('time', gpu, TABLE_TARGET_S, False, ' s')}")]


def _cloud_zip(path, n: int, seed: int, noise: float) -> None:
    """A coloured bumpy torus of ``n`` points as a zipped ASCII PLY (x y z red green blue)."""
    import zipfile

    g = np.random.default_rng(seed)
    u, v = np.random.default_rng(0).random((2, n)) * 2 * np.pi
    r = 0.2 + 0.01 * np.sin(12 * u)
    p = np.stack([(0.5 + r * np.cos(v)) * np.cos(u), (0.5 + r * np.cos(v)) * np.sin(u), r * np.sin(v)], 1)
    p = np.round((p + g.normal(0, noise, p.shape)) * 1000)
    c = np.clip(128 + 100 * np.sin(p / 90) + g.normal(0, 40 * noise / 0.002, p.shape), 0, 255).astype(int)
    head = f"ply\nformat ascii 1.0\nelement vertex {n}\nproperty float x\nproperty float y\nproperty float z\n" \
           "property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n"
    body = "\n".join(f"{a:.0f} {b:.0f} {z:.0f} {x} {y} {w}" for (a, b, z), (x, y, w) in zip(p, c))
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("cloud.ply", head + body + "\n")


def point_rows(n: int = 300_000) -> list[dict]:
    """Row 5: the point-cloud feature table (native splats) vs meshing + the mesh table."""
    import tempfile
    from pathlib import Path

    from lit3d.features import point_table as point_features
    from lit3d.features.table import FeatureConfig, feature_table
    from lit3d.render.convert import to_mesh
    from lit3d.render.point_clouds import load_points

    from dataclasses import replace

    cfg = FeatureConfig()
    workers = cfg.workers or default_threads()
    with tempfile.TemporaryDirectory() as tmp, num_threads(default_threads()):
        ref, dist = Path(tmp) / "ref.zip", Path(tmp) / "dist.zip"
        _cloud_zip(ref, n, 0, 0.0)
        _cloud_zip(dist, n, 1, 0.002)

        def ours_once():
            point_features._FRAMES.clear()  # no memoised local frames: the full cost of a new pair
            return feature_table(ref, dist, cfg)

        ours = median_time(ours_once, repeats=1, warmup=0)
        n_feat = len(ours_once().features)

        def meshed_once():
            pr, pd = load_points(ref).points, load_points(dist).points
            return feature_table(to_mesh(pr), to_mesh(pd), cfg)

        base = median_time(meshed_once, repeats=1, warmup=0)

        def without_new_once():
            point_features._FRAMES.clear()
            return feature_table(ref, dist, replace(cfg, colour_measures=(), point_measures=()))

        before = median_time(without_new_once, repeats=1, warmup=0)
    extra = [row(f"quality feature table, pair of {n // 1000}k-point coloured clouds: with the colour measures "
                 "(CIEDE2000; piq FSIMc, VIF, GMSD, HaarPSI, MDSI, VSI) and the field's metrics (PointSSIM, PCQM)",
                 CMD, ours, before, baseline_name="the same table without them", threads=workers,
                 note=f"{target_note('time', ours, TABLE_TARGET_S, False, ' s')}; nothing memoised; one run each")]
    return extra + [row(f"quality feature table, pair of {n // 1000}k-point coloured clouds (zipped ASCII PLY), native "
                f"splats, 36 styles x 2 shadings x 12 views, 256^2, all measures + D1/D2/Y-PSNR, PointSSIM, PCQM "
                f"({n_feat} features)",
                CMD, ours, base, baseline_name="mesh both clouds (96^3 grid) + mesh table", threads=workers,
                note=f"{target_note('time', ours, TABLE_TARGET_S, False, ' s')}; includes loading, PCA normals "
                     "and splatting of both clouds (nothing memoised); one run each")]


if __name__ == "__main__":
    for r in run():
        print(r)
