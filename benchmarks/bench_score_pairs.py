"""``lit3d-score --pairs`` (10 pairs in one process) against 10 separate ``lit3d-score`` calls.

Both sides run the installed console script as subprocesses, with ``--no-cache`` (no feature table
is read from the cache), on the same 10 pairs: icospheres of 1,280 faces, each with normal noise of
its own size. What ``--pairs`` saves is the per-call start-up (Python, torch, the EGL renderer); the
per-pair feature work is the same, so the ratio shrinks as that work grows (larger meshes, more
styles, bigger renders). Options: ``--size 128 --styles toon,jade,clay_studio`` so that the row
takes about a minute on 2 cores; the default (256 px, every style) costs several seconds per pair.

    python -m benchmarks.run score_pairs
"""
from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.common import row

CMD = "make bench"
N_PAIRS = 10
OPTIONS = ["--size", "128", "--styles", "toon,jade,clay_studio", "--no-cache"]


def write_pairs(folder: Path, n: int = N_PAIRS) -> tuple[Path, list[tuple[Path, Path]]]:
    """``n`` (reference .obj, distorted .ply) pairs in ``folder`` and the TSV file listing them."""
    import trimesh

    pairs = []
    for i in range(n):
        ref = trimesh.creation.icosphere(3, radius=1.0 + 0.05 * i)
        noise = np.random.default_rng(i).normal(0, 0.005 * (i + 1), (len(ref.vertices), 1))
        dist = trimesh.Trimesh(ref.vertices + ref.vertex_normals * noise, ref.faces, process=False)
        pair = (folder / f"ref_{i:02d}.obj", folder / f"dist_{i:02d}.ply")
        ref.export(pair[0])
        dist.export(pair[1])
        pairs.append(pair)
    tsv = folder / "pairs.tsv"
    tsv.write_text("".join(f"{r.name}\t{d.name}\n" for r, d in pairs))
    return tsv, pairs


def _seconds(args: list[str], env: dict) -> float:
    t0 = time.perf_counter()
    subprocess.run(args, check=True, capture_output=True, text=True, env=env, timeout=900)
    return time.perf_counter() - t0


def run() -> list[dict]:
    exe = str(Path(sys.executable).parent / "lit3d-score")
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        tsv, pairs = write_pairs(folder)
        env = {**os.environ, "LIT3D_CACHE": str(folder / "cache")}
        ours = _seconds([exe, "--pairs", str(tsv), *OPTIONS], env)
        separate = sum(_seconds([exe, str(r), str(d), *OPTIONS], env) for r, d in pairs)
    return [row(f"lit3d-score: {N_PAIRS} mesh pairs with --pairs (one process) vs {N_PAIRS} separate calls", CMD,
                ours, separate, baseline_name=f"{N_PAIRS} separate lit3d-score calls",
                note=f"{ours / N_PAIRS:.2f} s vs {separate / N_PAIRS:.2f} s a pair, wall time of the console "
                     f"script with start-up; 1,280-face icospheres, {' '.join(OPTIONS)}: what --pairs saves is "
                     "the start-up of each call (Python, torch, EGL), so the ratio is smaller where a pair's "
                     "features take longer (default 256 px, all styles)")]


if __name__ == "__main__":
    for r in run():
        print(r)
