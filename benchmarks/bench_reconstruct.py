"""lit3d-reconstruct: time per depth image on CPU, demo geometry (16^3 -> 64^3).

One row: the pipeline of :func:`lit3d.reconstruct.pipeline.reconstruct` (cut, back-projection,
placement + partial grid, completion network, threshold, marching cubes to a camera-frame mesh)
on a 320x240 depth render of the Stanford bunny through the 3D-RecGAN++ camera, with the demo
completion net (the weights do not change the time; the demo checkpoint is used when
``logs/demo/train/checkpoints/best-*.ckpt`` exists, else freshly built demo-size nets). The
note gives the step breakdown and the cost of the picture, which the CLI writes too.
No baseline: the network forward alone is given in the note (the rest is the pipeline's overhead).
"""
from __future__ import annotations

import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

from benchmarks.common import num_threads, row

CMD = "make bench"
REPO = Path(__file__).resolve().parents[1]
MESH = REPO.parent / "shared" / "data" / "meshes" / "bunny.obj"


def _completer():
    from benchmarks.bench_completion import _cfg
    from lit3d.runtime.build import build_task
    from lit3d.reconstruct.grid import GridGeometry
    from lit3d.reconstruct.pipeline import Completer, load_completer

    found = sorted((REPO / "logs" / "demo" / "train" / "checkpoints").glob("best-*.ckpt"))
    if found:
        return load_completer(found[-1]), "demo checkpoint"
    cfg = _cfg("completion_demo", tempfile.mkdtemp())
    task = build_task(cfg.task).eval()
    geom = GridGeometry.from_checkpoint({"source": "synth", "target_res": 64, "input_factor": 4}, task.net_cfg)
    return Completer(task, 0.5, geom, "<untrained demo nets>", "cpu"), "untrained demo-size nets"


def _mesh():
    import trimesh

    if MESH.is_file():
        return trimesh.load(MESH, force="mesh"), "Stanford bunny"
    return trimesh.creation.capsule(height=0.6, radius=0.25), "capsule (../shared/data absent)"


def run() -> list[dict]:
    from lit3d.reconstruct.backproject import RECGAN_FOV_DEG, Intrinsics
    from lit3d.reconstruct.figure import figure_png
    from lit3d.reconstruct.pipeline import reconstruct
    from lit3d.reconstruct.synthetic import pose_in_front, render_depth_pinhole

    completer, source = _completer()
    mesh, mesh_name = _mesh()
    intr = Intrinsics.from_fov(RECGAN_FOV_DEG, 320, 240)
    depth = render_depth_pinhole(pose_in_front(mesh), intr, 320, 240)
    threads = 2
    with num_threads(threads):
        reconstruct(depth, intr, completer)  # warm-up
        totals, steps = [], []
        for _ in range(5):
            t0 = time.perf_counter()
            res = reconstruct(depth, intr, completer)
            totals.append(time.perf_counter() - t0)
            steps.append(res.timings)
        partial = torch.from_numpy(res.partial.astype(np.float32))[None, None]
        net = []
        for _ in range(5):
            t0 = time.perf_counter()
            with torch.inference_mode():
                completer.task(partial)
            net.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        figure_png(depth, res.keep, res.points, res.mesh, "bench", 256)
        fig = time.perf_counter() - t0
    ours, base = statistics.median(totals), statistics.median(net)
    extra = f"network forward alone {base * 1000:.0f} ms; "
    med = {k: statistics.median(s[k] for s in steps) for k in steps[0]}
    breakdown = ", ".join(f"{k} {v * 1000:.0f} ms" for k, v in med.items())
    note = (f"320x240 depth of the {mesh_name} (3D-RecGAN++ camera), {len(res.points)} visible points, {source}; "
            f"{extra}steps (median): {breakdown}; the 4x2-panel picture adds {fig:.1f} s (once, after warm-up)")
    return [row("reconstruct one depth image -> mesh, demo 16^3->64^3, fp32, CPU", CMD, ours, None,
                unit="s/image", note=note, threads=threads)]


if __name__ == "__main__":
    for r in run():
        print(r)
