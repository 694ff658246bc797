"""``lit3d-summary --pooled`` and ``lit3d-summary --over-runs``: the canonical task's cross-validation summaries.

    lit3d-summary --pooled RUN_DIR... --seeds 0 1 2 3 4 [--rows model input chance] --out DIR
    lit3d-summary --pooled --seeds 0 1 2 3 4 --out DIR -- experiment=canonical_tosca data.root=PATH   # non-learned rows
    lit3d-summary --over-runs SWEEP_DIR... [--rows model input chance] [--out FILE.md] [--confusion model]

``--pooled``: every held-out item scored once (the folds' ``heldout.npz`` merged), every row on the same items
and codebook seeds, mean ± sd over the seeds: :func:`lit3d.canonical.pooled.run`, the same as at the end of
``+sweep=canonical_cv``; writes ``DIR/pooled_results.md`` and ``DIR/pooled.json``. Without run dirs, the Hydra
overrides after ``--`` compose the data and the rows are the non-learned ones. ``--over-runs``: mean ± sd over
training runs of those ``pooled.json`` files (:mod:`lit3d.canonical.over_runs`). A bad input (a run dir without
``heldout.npz``, folds that do not cover the data, a missing or bad ``pooled.json``) is one line, exit 2, and
nothing is written.
"""
from __future__ import annotations

import argparse
import logging
from collections.abc import Sequence
from pathlib import Path

from lit3d.cli.about import run_argparse_cli, version_line

OPTIONS = ("--pooled", "--over-runs")


def pooled_parser(prog: str = "lit3d-summary") -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog=prog, description="Pooled, cross-validated retrieval of the canonical task "
                                "(run dirs of one cross-validation; without them: the non-learned rows of the "
                                "config that the Hydra overrides after -- compose).")
    p.add_argument("--pooled", nargs="*", type=Path, required=True, metavar="RUN_DIR",
                   help="run dirs with heldout.npz (one per fold; lit3d-train or lit3d-eval of the canonical task)")
    p.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2, 3, 4], help="codebook seeds (default 0 1 2 3 4)")
    p.add_argument("--out", type=Path, required=True, help="folder for pooled_results.md and pooled.json")
    p.add_argument("--rows", nargs="+", default=None, help="only these rows (e.g. model input chance shapedna)")
    p.add_argument("--mesh-baselines", nargs="*", default=None,
                   help="canonical-form rows (cmds smacof nmds gps posed; default: evaluation.mesh_baselines)")
    p.add_argument("--allow-partial", action="store_true", help="score folds that do not cover every item")
    p.add_argument("--fold-test", action="store_true",
                   help="without run dirs: only the test split of data.split.fold (not every fold's held-out items)")
    p.add_argument("--depth-row", action="append", default=[], metavar="ROW=DIR",
                   help="one more depth row: DIR/<subject>_pose<pose>_body_canonical_depth.npy per item")
    p.add_argument("--smooth-px", type=float, default=None, metavar="SIGMA",
                   help="smooth the prediction's depth inside its silhouette first (evaluation.prediction_smooth_px)")
    p.add_argument("--debug", action="store_true", help="show full tracebacks")
    p.add_argument("--version", action="version", version=version_line("lit3d-summary"))
    return p


def over_runs_parser(prog: str = "lit3d-summary") -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog=prog, description="Mean ± sd over training runs of the pooled canonical "
                                "results (one pooled.json per run).")
    p.add_argument("--over-runs", nargs="+", required=True, metavar="SWEEP_DIR",
                   help="dirs with pooled.json (one per training run: +sweep=canonical_cv or lit3d-summary --pooled)")
    p.add_argument("--rows", nargs="+", default=["model", "input"], help="rows of pooled.json (default model input)")
    p.add_argument("--out", type=Path, help="also write the tables to this .md file")
    p.add_argument("--confusion", metavar="ROW", help="add the nearest-canonical-mask confusion of this row (e.g. model)")
    p.add_argument("--debug", action="store_true", help="show full tracebacks")
    p.add_argument("--version", action="version", version=version_line("lit3d-summary"))
    return p


def depth_rows_of(specs: Sequence[str]) -> dict[str, str]:
    """``{row: folder}`` of ``--depth-row ROW=DIR`` values; ValueError for one without ``=``."""
    bad = [s for s in specs if "=" not in s or not s.split("=", 1)[0]]
    if bad:
        raise ValueError(f"--depth-row {bad[0]}: expected ROW=DIR")
    return dict(s.split("=", 1) for s in specs)


def run_pooled(args: argparse.Namespace, overrides: Sequence[str] = ()) -> int:
    from lit3d.canonical.pooled import run

    depth_rows = depth_rows_of(args.depth_row)
    if not args.pooled and not overrides:
        raise ValueError("--pooled: give run dirs, or Hydra overrides after -- for the non-learned rows")
    if args.out.exists() and not args.out.is_dir():
        raise ValueError(f"{args.out}: --out is a file, not a folder")
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    path = run(args.pooled, args.seeds, args.out, list(overrides), args.rows, strict=not args.allow_partial,
               mesh_baselines=args.mesh_baselines, fold_test=args.fold_test, depth_rows=depth_rows,
               smooth_px=args.smooth_px)
    print(path.read_text(encoding="utf-8"))
    return 0


def run_over_runs(args: argparse.Namespace) -> int:
    from lit3d.canonical.over_runs import confusion, confusion_markdown, load, markdown, over_runs
    from lit3d.utils.io import atomic_write_text

    runs = load(args.over_runs)
    text = markdown(over_runs(runs, args.rows), [Path(d).name for d in args.over_runs])
    if args.confusion:
        threshold = float(runs[0].get("settings", {}).get("mask_threshold", 0.5))
        text += "\n" + confusion_markdown(*confusion(args.over_runs, args.confusion, threshold))
    print(text, end="")
    if args.out:
        atomic_write_text(args.out, text)
    return 0


def main(argv: Sequence[str], prog: str = "lit3d-summary") -> int | None:
    """The exit status of ``--pooled`` or ``--over-runs`` when ``argv`` names one, else None (the Hydra
    ``lit3d-summary`` of a config). Hydra overrides follow ``--`` (``--pooled`` without run dirs)."""
    argv = list(argv)
    cut = argv.index("--") if "--" in argv else len(argv)
    options, overrides = argv[:cut], argv[cut + 1:]
    if "--pooled" in options:  # with --over-runs too: argparse's one line on the unrecognised option
        return run_argparse_cli(prog, pooled_parser(prog), lambda a: run_pooled(a, overrides), options)
    if "--over-runs" in options:  # anything after -- is an unrecognised argument
        return run_argparse_cli(prog, over_runs_parser(prog), run_over_runs, argv)
    return None
