"""Score lit3d-reconstruct's completion chain on FAUST people as the body fit is scored.

    python -m studies.body.faust_chain --faust ../shared/data/faust_a --ckpt COMPLETION_CKPT --out DIR

Every ``faust_a`` mesh is scaled, placed and rendered exactly as ``python -m studies.body.evaluate --faust``
does (:func:`lit3d.body.fit_scores.faust_meshes`: the subject's pose 0 stands 1.7 m tall, 3.2 m in front of
the 3D-RecGAN++ camera, one 320x240 front depth image). The depth image goes through
:func:`lit3d.complete` (``lit3d-reconstruct``'s steps: cut the object, back-project, voxelise, complete,
mesh in the camera frame); the completed mesh is scored against the whole FAUST surface (its back
included) with the body fit's measures (:func:`lit3d.body.fit_scores.chamfer_fscore`: two-sided Chamfer
in mm, F-score at 1% and 2% of the height), on ``--samples`` area-uniform samples of each mesh.

Writes ``DIR/chain_eval.json`` (every mesh) and ``DIR/chain_eval.md`` (median [quartiles]), both rewritten
after every mesh (a stopped run keeps what it measured).
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import torch

import lit3d
from lit3d.body.fit_scores import FAUST_HEIGHT, chamfer_fscore, faust_meshes, in_mm, surface_points
from lit3d.body.report import spread
from lit3d.body_fit.synthetic import Camera, render

TAUS = (0.01 * FAUST_HEIGHT, 0.02 * FAUST_HEIGHT)
MEASURES = ("chamfer", "f@0.017", "f@0.034")


def score_mesh(stem: str, verts: np.ndarray, faces: np.ndarray, completer, cam: Camera, samples: int) -> dict:
    """One FAUST mesh (camera frame, metres) through the chain: ``{"item", "chamfer" (mm), "f@t"..., "seconds"}``."""
    depth = render(verts, faces, cam)
    t = time.process_time()
    result = lit3d.complete(depth, completer, cam)
    seconds = time.process_time() - t
    truth = surface_points(verts, faces, samples)
    pred = surface_points(np.asarray(result.mesh.vertices), np.asarray(result.mesh.faces), samples, 1)
    return {"item": stem, "seconds": seconds, "faces": int(len(result.mesh.faces)),
            **in_mm(chamfer_fscore(pred, truth, TAUS))}


def markdown(rows: list[dict], ckpt: Path) -> str:
    """Median [quartiles] of each measure over the scored meshes, as the body fit's FAUST table."""
    cells = []
    for k in (*MEASURES, "seconds"):
        s = spread([r[k] for r in rows])
        fmt = ".0f" if k == "chamfer" else ".2f"
        cells.append(f"{s['median']:{fmt}} [{s['q25']:{fmt}}-{s['q75']:{fmt}}]")
    return (f"# lit3d-reconstruct's completion chain on FAUST ({len(rows)} meshes)\n\ncheckpoint: `{ckpt}`\n\n"
            "| method | Chamfer (mm) | F@1% | F@2% | CPU s/image |\n|---|---|---|---|---|\n"
            f"| completion chain | {' | '.join(cells)} |\n")


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--faust", type=Path, required=True, help="FAUST folder (e.g. ../shared/data/faust_a)")
    ap.add_argument("--ckpt", type=Path, required=True, help="completion checkpoint (lit3d-train task=completion)")
    ap.add_argument("--out", type=Path, required=True, help="folder for chain_eval.json and chain_eval.md")
    ap.add_argument("--samples", type=int, default=20000, help="surface samples per mesh")
    ap.add_argument("--limit", type=int, default=0, help="at most K meshes (0: all)")
    ap.add_argument("--threads", type=int, default=1, help="torch CPU threads")
    args = ap.parse_args(argv)
    torch.set_num_threads(args.threads)
    completer, cam = lit3d.load(args.ckpt), Camera.default()
    meshes = faust_meshes(args.faust)
    rows: list[dict] = []
    args.out.mkdir(parents=True, exist_ok=True)
    for stem, verts, faces in meshes[:args.limit] if args.limit else meshes:
        rows.append(score_mesh(stem, verts, faces, completer, cam, args.samples))
        r = rows[-1]
        print(f"{stem}: Chamfer {r['chamfer']:.0f} mm, F@1% {r['f@0.017']:.2f}, F@2% {r['f@0.034']:.2f}, "
              f"{r['seconds']:.1f} s CPU", flush=True)
        (args.out / "chain_eval.json").write_text(json.dumps({"ckpt": str(args.ckpt), "items": rows}, indent=1))
        (args.out / "chain_eval.md").write_text(markdown(rows, args.ckpt))
    print(markdown(rows, args.ckpt))


if __name__ == "__main__":
    main()
