"""Measure the Anny body fit: held-out Anny people and FAUST, with baselines.

    python -m studies.body.evaluate --out DIR [--anny N] [--faust ../shared/data/faust_a] [--multi-start]

Camera: the ``lit3d-reconstruct`` default, the 3D-RecGAN++ pinhole (fov 49.124 degrees across both
sides of a 320x240 image, centred), the person 3.2 m in front of it, facing it.

- **Held-out Anny people** (``--anny N``): subject ``i`` = phenotype ``i`` of draw ``--body-seed``
  (Anny's adult shape distribution, as ``conf/data/anny.yaml``) in its own pose ``i`` of draw
  ``--pose-seed`` (:func:`lit3d.body_model.bodies.sample_pose`, yaw included; ``--poses varied``:
  :func:`lit3d.body_fit.poses.draw_pose`'s mix, people also lying, folded and upside down); training
  draws use seed 0 (the regressor's 7), these 1000+. The depth image gets the ``recgan`` sensor's noise
  (:data:`lit3d.sensing.sensor.SENSORS`), whose figures are in voxels of a 256 grid: one voxel
  is taken as the person's longest side / 256 (~6.6 mm): misregistration (the body rendered
  shifted by U(-0.75, 0.75) voxels per axis against its truth), range noise (sd 0.25 voxel) and
  15% holes in blobs of 8 voxels (:func:`lit3d.sensing.sensor.hole_mask`, blob size converted
  to pixels at the body's depth). Measured: median per-vertex error (mm) of the canonical body
  (rest pose, fitted phenotype and scale, about Anny's origin) against the true rest-pose body,
  the same for the posed body in the camera frame, mean abs phenotype error per label, fit CPU
  seconds. Beside: the mean body (phenotype .5, no pose; placed and scaled by the fit's rigid stage).
- **FAUST** (``--faust DIR``): every ``subject<S>_pose<P>`` mesh scaled so that its subject's pose 0
  stands 1.7 m tall (y extent), centred on its bounding box, seen from the front; the fitted posed
  body against the whole FAUST surface (its back included): two-sided Chamfer (mean of the two
  directed mean distances, mm) and F-score at 1% and 2% of the height (17 and 34 mm), on
  ``--samples`` area-uniform surface samples of each mesh. Beside: the visible input points alone
  (as the predicted set) and the mean body. The canonical depth images (``<stem>_body_canonical_depth.npy``,
  :func:`lit3d.body_fit.results.canonical_depth`) go to ``DIR/faust_canonical`` for the retrieval
  row (``lit3d-summary --pooled --depth-row body_fit=DIR/faust_canonical ...``).

``--multi-start``: :func:`lit3d.body_fit.fit.fit_best` (four starts probed, the lowest loss goes on) in
place of the single fit from the mean body; CPU seconds count every start.

``--init CKPT`` (a :mod:`lit3d.body_fit.regressor` checkpoint): two more rows beside the optimisation
alone: the regressor alone (its parameters, no step) and the regressor + refinement
(:func:`lit3d.body_fit.regressor.fit_from_regressor`, ``--refine-global`` + ``--refine-full`` steps),
each with its CPU seconds (the crop and network included).

Writes ``DIR/body_eval.json`` (every item) and ``DIR/body_eval.md`` (medians, quartiles), both
rewritten after every item (a stopped run keeps what it measured).
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

from lit3d.body.fit_scores import DISTANCE, anny_items, faust_items
from lit3d.body.report import markdown, summarise
from lit3d.body_fit.model import Body
from lit3d.body_fit.poses import POSE_MIXES
from lit3d.body_fit.regressor import REFINE_FULL_ITERS, REFINE_GLOBAL_ITERS, load_regressor, refine_config
from lit3d.body_fit.synthetic import HEIGHT, WIDTH, Camera
from lit3d.sensing.sensor import SENSORS


def main(argv: list[str] | None = None) -> None:
    import sys

    import torch

    ap = argparse.ArgumentParser(prog="python -m studies.body.evaluate", description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, required=True, help="folder for body_eval.json and body_eval.md")
    ap.add_argument("--anny", type=int, default=20, help="held-out Anny people (0: none)")
    ap.add_argument("--body-seed", type=int, default=1000, help="phenotype draw (training uses 0)")
    ap.add_argument("--pose-seed", type=int, default=1000, help="pose draw (training uses 0)")
    ap.add_argument("--poses", default="upright", choices=sorted(POSE_MIXES),
                    help="pose mix of the Anny people (lit3d.body_fit.poses): upright as the data source, or varied")
    ap.add_argument("--sensor", default="recgan", choices=sorted(SENSORS), help="noise model of the Anny depth images")
    ap.add_argument("--faust", type=Path, default=None, help="FAUST folder (e.g. ../shared/data/faust_a)")
    ap.add_argument("--faust-first", type=int, default=0, help="skip the first K FAUST meshes (pose-major order)")
    ap.add_argument("--faust-limit", type=int, default=0, help="at most K FAUST meshes (0: all)")
    ap.add_argument("--samples", type=int, default=20000, help="surface samples per mesh for Chamfer/F-score")
    ap.add_argument("--multi-start", action="store_true",
                    help="fit from 4 starts (mean body, yaw -/+0.4 rad, arms lowered; lit3d.body_fit.fit.fit_best)")
    ap.add_argument("--init", type=Path, default=None, help="body regressor checkpoint (lit3d-train experiment=body_regressor): "
                    "adds the rows 'regressor alone' and 'regressor + refinement'")
    ap.add_argument("--refine-global", type=int, default=REFINE_GLOBAL_ITERS, help="rigid steps of the refinement")
    ap.add_argument("--refine-full", type=int, default=REFINE_FULL_ITERS, help="full steps of the refinement")
    ap.add_argument("--refine-poor", type=int, default=0,
                    help="full steps more where the refinement is flagged poor (0: none)")
    ap.add_argument("--threads", type=int, default=1, help="torch CPU threads")
    args = ap.parse_args(argv)
    torch.set_num_threads(args.threads)

    def say(line):
        print(line, file=sys.stderr, flush=True)

    init = None if args.init is None else (load_regressor(args.init),
                                           refine_config(args.refine_global, args.refine_full,
                                                         poor_extra_iters=args.refine_poor))
    cam, body = Camera.default(), Body()
    args.out.mkdir(parents=True, exist_ok=True)
    meta = {"command": "python -m studies.body.evaluate " + " ".join(argv if argv is not None else sys.argv[1:]),
            "body_seed": args.body_seed, "pose_seed": args.pose_seed, "poses": args.poses, "sensor": args.sensor,
            "starts": "4 starts, best probe kept" if args.multi_start else "one start: the mean body",
            "camera": {**cam.__dict__, "width": WIDTH, "height": HEIGHT, "distance_m": DISTANCE}, "threads": args.threads}
    if init is not None:
        meta.update(init=str(args.init), refine=f"{args.refine_global} + {args.refine_full} steps"
                    + (f", {args.refine_poor} more where flagged poor" if args.refine_poor else ""))
    anny: list[dict] = []
    faust: list[dict] = []

    def write() -> str:  # after every item: a stopped run keeps what it measured
        summary = summarise(anny, faust)
        (args.out / "body_eval.json").write_text(json.dumps({"meta": meta, "summary": summary, "anny": anny,
                                                            "faust": faust}, indent=1), "utf-8")
        text = markdown(summary, meta)
        (args.out / "body_eval.md").write_text(text, "utf-8")
        return text

    def note(line):
        say(line)
        write()

    if args.anny:
        anny_items(body, args.anny, args.body_seed, args.pose_seed, cam, args.sensor, note, anny, args.multi_start, init,
                   args.poses)
    if args.faust is not None:
        faust_items(body, args.faust, cam, args.samples, args.out / "faust_canonical", note,
                    args.faust_limit, faust, args.multi_start, args.faust_first, init)
    print(write())


if __name__ == "__main__":
    main()
