"""Pooled, cross-validated retrieval of the canonical task by hand (the protocol:
:mod:`lit3d.canonical.pooled`; the same at the end of ``+sweep=canonical_cv``).

    python -m studies.canonical.pooled RUN_DIR... --seeds 0 1 2 3 4 --out DIR
    python -m studies.canonical.pooled --seeds 0 1 2 3 4 --out DIR -- experiment=canonical_tosca \\
        data.root=../shared/data/tosca8k data.render.view_mode=broadside        # non-learned rows only

Run dirs: the folds' ``heldout.npz`` pooled; without them, the Hydra overrides after ``--`` compose the
data and the rows are the non-learned ones. Writes ``DIR/pooled_results.md`` and ``DIR/pooled.json``.
"""
from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

from lit3d.canonical.pooled import run


def main(argv: list[str] | None = None) -> None:
    argv = list(sys.argv[1:] if argv is None else argv)
    overrides = argv[argv.index("--") + 1:] if "--" in argv else []
    argv = argv[:argv.index("--")] if "--" in argv else argv
    parser = argparse.ArgumentParser(prog="python -m studies.canonical.pooled", description=__doc__.split("\n")[0])
    parser.add_argument("runs", nargs="*", type=Path, help="run dirs with heldout.npz (one per fold)")
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2, 3, 4], help="codebook seeds")
    parser.add_argument("--out", type=Path, required=True, help="folder for pooled_results.md and pooled.json")
    parser.add_argument("--rows", nargs="+", default=None, help="only these rows (e.g. input cmds shapedna)")
    parser.add_argument("--mesh-baselines", nargs="*", default=None,
                        help="canonical-form rows (cmds smacof nmds gps posed; default: evaluation.mesh_baselines)")
    parser.add_argument("--allow-partial", action="store_true", help="score folds that do not cover every item")
    parser.add_argument("--fold-test", action="store_true",
                        help="without run dirs: only the test split of data.split.fold (not every fold's held-out items)")
    parser.add_argument("--depth-row", action="append", default=[], metavar="ROW=DIR",
                        help="one more depth row: DIR/<subject>_pose<pose>_body_canonical_depth.npy per item")
    parser.add_argument("--smooth-px", type=float, default=None, metavar="SIGMA",
                        help="smooth the prediction's depth inside its silhouette first (evaluation.prediction_smooth_px)")
    args = parser.parse_args(argv)
    depth_rows = dict(r.split("=", 1) for r in args.depth_row if "=" in r)
    if len(depth_rows) != len(args.depth_row):
        parser.error("--depth-row: expected ROW=DIR")
    if not args.runs and not overrides:
        parser.error("give run dirs, or Hydra overrides after -- for the non-learned rows")
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    print(run(args.runs, args.seeds, args.out, overrides, args.rows, strict=not args.allow_partial,
              mesh_baselines=args.mesh_baselines, fold_test=args.fold_test, depth_rows=depth_rows,
              smooth_px=args.smooth_px).read_text())


if __name__ == "__main__":
    main()
