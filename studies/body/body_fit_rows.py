"""The body fit's canonical depth images for the held-out items of a canonical config (the
``body_fit`` row beyond FAUST: held-out Anny people, TOSCA's humans).

    python -m studies.body.body_fit_rows --out DIR [--init REGRESSOR_CKPT] [--worker I --workers K] \\
        -- experiment=canonical_humans data.data_dir=... data.source.pose_draw=per_subject
    lit3d-summary --pooled --fold-test --rows input body_fit chance --depth-row body_fit=DIR \\
        --seeds 0 1 2 3 4 --out POOLED -- experiment=canonical_humans data.data_dir=... data.source.pose_draw=per_subject

The Hydra overrides after ``--`` compose the canonical data as ``lit3d-train`` would
(:func:`lit3d.canonical.pooled.compose`); every (subject, pose) of its test split (``--all``: every
held-out item of the folds) is taken at full resolution (``raw_mesh``: y up, facing +z), centred on its
box, scaled so that the subject's rest pose stands ``--height`` m tall when the source is not metric
(``--metric``: keep its units, e.g. Anny's metres), placed 3.2 m in front of the 3D-RecGAN++ camera and
rendered as one 320x240 depth image (:mod:`lit3d.body_fit.synthetic`, as ``python -m studies.body.evaluate
--faust`` does). The body is fitted from the mean body (``DIR``) and, with ``--init``, from the regressor + its
refinement (``DIR_refined``); each fit's canonical depth image, rendered as the canonical task renders its targets
(:func:`lit3d.body_fit.results.fit_outputs`), is saved as ``<subject>_pose<pose>_body_canonical_depth.npy`` (and
its quality as ``_body.json``), the name :func:`lit3d.canonical.pooled.folder_depths` reads. Items already there are skipped (a
stopped run resumes); ``--worker I --workers K`` takes every K-th item from the I-th (parallel runs).
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import torch
from omegaconf import OmegaConf

from lit3d.body.fit_scores import FAUST_HEIGHT, camera_frame, fit
from lit3d.body_fit.model import Body
from lit3d.body_fit.regressor import load_regressor, refine_config
from lit3d.body_fit.results import fit_outputs
from lit3d.body_fit.synthetic import Camera, render
from lit3d.canonical.pooled import FOLDER_DEPTH_SUFFIX, build_datamodule, compose


def refined_dir(out: Path) -> Path:
    """Where the regressor + refinement fits go (``--init``): ``OUT_refined`` beside ``OUT``."""
    return out.parent / f"{out.name}_refined"


def held_out_pairs(dm, every_fold: bool) -> list[tuple[str, int]]:
    """Sorted unique (subject, pose) of the test split (``every_fold``: every held-out item)."""
    records = dm.held_out_records() if every_fold else dm.splits["test"]
    return sorted({(str(r["subject"]), int(r["pose"])) for r in records})


def main(argv: list[str] | None = None) -> None:
    argv = sys.argv[1:] if argv is None else argv
    ours, overrides = (argv[:argv.index("--")], argv[argv.index("--") + 1:]) if "--" in argv else (argv, [])
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, required=True, help="folder of the canonical depth images")
    ap.add_argument("--init", type=Path, default=None, help="body regressor checkpoint (lit3d-train experiment=body_regressor)")
    ap.add_argument("--refine-poor", type=int, default=0, help="with --init: full steps more where flagged poor")
    ap.add_argument("--metric", action="store_true", help="the source's units are metres (Anny): no rescaling")
    ap.add_argument("--height", type=float, default=FAUST_HEIGHT, help="rest-pose height in metres otherwise")
    ap.add_argument("--all", action="store_true", help="every held-out item of the folds, not the test split")
    ap.add_argument("--worker", type=int, default=0)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--threads", type=int, default=1, help="torch CPU threads")
    args = ap.parse_args(ours)
    torch.set_num_threads(args.threads)
    cfg = compose(overrides)
    dm = build_datamodule(OmegaConf.to_container(cfg.data, resolve=True))
    dm.prepare_data()
    dm.setup()
    pairs = held_out_pairs(dm, args.all)[args.worker::args.workers]
    init = None if args.init is None else (load_regressor(args.init), refine_config(poor_extra_iters=args.refine_poor))
    cam, body = Camera.default(), Body()
    args.out.mkdir(parents=True, exist_ok=True)
    scales: dict[str, float] = {}
    for subject, pose in pairs:
        target = args.out / f"{subject}_pose{pose}{FOLDER_DEPTH_SUFFIX}"
        if target.is_file() and (init is None or (refined_dir(args.out) / target.name).is_file()):
            continue
        if subject not in scales:
            rest = np.asarray(dm.renderer.raw_mesh(subject, "canonical")[0])
            scales[subject] = 1.0 if args.metric else args.height / float(np.ptp(rest[:, 1]))
        verts, faces = dm.renderer.raw_mesh(subject, pose)
        depth = render(camera_frame(verts, scales[subject]), np.asarray(faces), cam)
        r = fit(body, depth, cam, f"{subject} pose {pose}", init=init)
        fits = {args.out: ("fit", r["cpu_s"])}
        if init is not None:
            fits[refined_dir(args.out)] = ("refined", r["refined_cpu_s"])
        for folder, (name, cpu_s) in fits.items():
            out = fit_outputs(body, r[name], r["obs"])
            folder.mkdir(parents=True, exist_ok=True)
            (folder / f"{subject}_pose{pose}_body.json").write_text(json.dumps(
                {"cpu_s": cpu_s, **{k: (v.item() if hasattr(v, "item") else v) for k, v in out.quality.items()
                                    if np.isscalar(v)}}))
            tmp = folder / f"{subject}_pose{pose}.tmp.npy"
            np.save(tmp, out.canonical_depth)
            tmp.replace(folder / target.name)
            print(f"{subject} pose {pose} ({name}): {cpu_s:.1f} s CPU, poor fit {out.quality['poor_fit']}", flush=True)


if __name__ == "__main__":
    main()
