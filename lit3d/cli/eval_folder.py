"""``lit3d-eval-folder PRED_DIR DATA_DIR --out OUT``: score another method's shape completions
against the targets of a prepared completion data split, with lit3d's test metrics;
``lit3d-eval-folder PRED_DIR --targets TARGET_DIR --out OUT``: against a folder of target meshes or grids.

Examples::

    lit3d-eval-folder preds/ data/completion_demo_sweethome3d --out eval_other/
    lit3d-eval-folder meshes/ data/completion_synth --out eval_onet/ --mesh-frame unit --name "ONet"
    lit3d-eval-folder grids/ DATA --out OUT --split test_same --threshold 0.4
    lit3d-eval-folder onet_meshes/ --targets gt_meshes/ --out eval_onet/ --name "ONet"
    lit3d-eval-folder pred_grids/ --targets gt_meshes/ --out OUT --mesh-frame voxel --resolution 128

Against a prepared cache (DATA_DIR): the prediction of the cached target
``DATA_DIR/items/<split>/<stem>.npz`` is ``PRED_DIR/<split>/<stem>.<ext>`` or ``PRED_DIR/<stem>.<ext>``:
a voxel grid (.npz/.npy, the target's shape, {0, 1} or probabilities in [0, 1]; an SDF under the npz
key 'sdf') or a mesh (.obj/.ply/.off in the grid's frame, see --mesh-frame). Splits with predictions
are scored (every target of a scored split needs one). Writes OUT/metrics.json and OUT/results.md:
the thesis-layout IoU tables (grid predictions) and the surface metrics (Chamfer-L1, F-score, normal
consistency) beside IoU, as lit3d-eval writes them for a checkpoint.

Against a folder of targets (--targets TARGET_DIR): PRED_DIR/<stem>.<ext> is paired with
TARGET_DIR/<stem>.<ext> by file stem (meshes .obj/.ply/.off, grids .npz/.npy; chair_01.obj with
chair_01.ply). Meshes are taken as stored (prediction and target in one frame and unit: nothing is
aligned or scaled); grids in the --mesh-frame frame. Every target needs a prediction; predictions
without a target are named and left out. Writes OUT/metrics.json (one row per pair, means with 95%
bootstrap intervals) and OUT/results.md: Chamfer-L1 (the two directions' mean distances averaged),
Chamfer-L2 (mean squared distances, summed), F-score at shares of the target's bounding-box diagonal,
normal consistency, and IoU where both are solids (grids or watertight meshes, voxelised at
--resolution, default evaluation.folder.iou_resolution of conf/task/completion.yaml).

Point count, F-score thresholds and seed default to evaluation.surface of conf/task/completion.yaml.
Bad input (a missing, unreadable, empty or wrongly shaped file, NaN vertices, no prepared data) ends
with one line naming the file and exit status 2, and nothing written.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from lit3d.cli.about import run_argparse_cli, version_line
from lit3d.runtime.compose import CONF_DIR

PROG = "lit3d-eval-folder"


def evaluation_defaults() -> dict:
    """``evaluation`` of ``conf/task/completion.yaml`` (``surface``: points, fscore_at, seed; ``folder``)."""
    from omegaconf import OmegaConf

    return OmegaConf.to_container(OmegaConf.load(Path(CONF_DIR) / "task" / "completion.yaml").evaluation)


def surface_defaults() -> dict:
    """``evaluation.surface`` of ``conf/task/completion.yaml`` (points, fscore_at, seed)."""
    return evaluation_defaults()["surface"]


def _parser() -> argparse.ArgumentParser:
    doc = __doc__.replace("``", "'")
    p = argparse.ArgumentParser(prog=PROG, description=doc.split("\n\n")[0],
                                epilog="\n\n".join(doc.split("\n\n")[1:]),
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("pred_dir", type=Path, help="folder of predictions (grids .npz/.npy or meshes .obj/.ply/.off)")
    p.add_argument("data_dir", type=Path, nargs="?", default=None,
                   help="prepared completion data (lit3d-data; holds manifest.json); or give --targets")
    p.add_argument("--targets", type=Path, default=None, metavar="TARGET_DIR",
                   help="instead of DATA_DIR: a folder of target meshes (.obj/.ply/.off) or grids (.npz/.npy), "
                        "paired with the predictions by file stem")
    p.add_argument("--out", type=Path, required=True, help="folder for metrics.json and results.md")
    p.add_argument("--split", action="append",  # checked against the data's test splits by score_folder
                   help="DATA_DIR only: score only this test split: test_same, test_cross, test_unseen or "
                        "test_unseen_cross (repeatable; default: every split with predictions)")
    p.add_argument("--name", default=None, help="the method's row label in results.md (default: PRED_DIR's name)")
    p.add_argument("--threshold", type=float, default=0.5, help="grid probabilities >= this are occupied (0.5)")
    p.add_argument("--mesh-frame", choices=("unit", "voxel"), default="unit",
                   help="meshes beside grids: 'unit' = the grid is the cube [-0.5, 0.5]^3 (default); "
                        "'voxel' = vertex (x, y, z) at grid index [x, y, z]")
    p.add_argument("--resolution", type=int, default=None,
                   help="--targets only: voxels a side of the grid two watertight meshes are voxelised on for "
                        "IoU (default evaluation.folder.iou_resolution)")
    p.add_argument("--points", type=int, default=None,
                   help="points sampled per surface (default evaluation.surface.points)")
    p.add_argument("--fscore-at", type=float, nargs="+", default=None,
                   help="F-score thresholds as fractions of the target's bounding-box diagonal "
                        "(default evaluation.surface.fscore_at)")
    p.add_argument("--debug", action="store_true", help="show full tracebacks")
    p.add_argument("--version", action="version", version=version_line(PROG))
    return p


def main(argv: list[str] | None = None) -> int:
    """Console script ``lit3d-eval-folder``."""
    return run_argparse_cli(PROG, _parser(), _run, argv)


def _check_mode(args) -> None:
    """Exactly one of DATA_DIR and --targets, each with its own options; a DATA_DIR without a manifest
    that holds shape files is pointed to --targets."""
    if (args.data_dir is None) == (args.targets is None):
        raise ValueError("give DATA_DIR (a prepared completion cache) or --targets TARGET_DIR (a folder of target "
                         "meshes or grids), one of the two" + ("" if args.data_dir is None else
                                                               f", not both ({args.data_dir} and {args.targets})"))
    if args.targets is not None and args.split:
        raise ValueError("--split: only with a prepared DATA_DIR (a folder of --targets has no splits)")
    if args.data_dir is not None and args.resolution is not None:
        raise ValueError("--resolution: only with --targets (DATA_DIR's targets are grids already)")
    if args.data_dir is not None and args.data_dir.is_dir() and not (args.data_dir / "manifest.json").exists():
        from lit3d.completion.target_pairs import SHAPE_SUFFIXES

        if any(p.suffix.lower() in SHAPE_SUFFIXES for p in args.data_dir.iterdir()):
            raise ValueError(f"{args.data_dir}: no prepared completion data (no manifest.json), but shape files: "
                             f"to score against a folder of targets, give it as --targets {args.data_dir}")


def _run(args) -> int:
    _check_mode(args)
    if args.targets is not None:
        return _run_targets(args)
    from lit3d.utils.io import check_targets, check_writable, write_json

    out = Path(args.out)
    check_targets([out / "metrics.json", out / "results.md"], [args.pred_dir, args.data_dir / "manifest.json"])
    check_writable(out, "--out")  # before any prediction is read; creates nothing
    from lit3d.completion.folder_eval import FolderScoring, score_folder

    surface = surface_defaults()
    cfg = FolderScoring(points=args.points or int(surface["points"]),
                        fscore_at=tuple(args.fscore_at or surface["fscore_at"]), seed=int(surface.get("seed", 0)),
                        threshold=args.threshold, mesh_frame=args.mesh_frame)
    metrics, info = score_folder(args.pred_dir, args.data_dir, cfg, args.split)
    name = args.name or args.pred_dir.resolve().name
    from datamodules.cache import read_manifest
    from lit3d.completion.report import write_results  # Lightning (through the module): after the inputs are read

    manifest = read_manifest(args.data_dir) or {}
    extra = {"pred_dir": str(args.pred_dir), "data_dir": str(args.data_dir), "method": name,
             "manifest_hash": manifest.get("manifest_hash"), "threshold": cfg.threshold,
             "mesh_frame": cfg.mesh_frame, "surface": {"points": cfg.points, "fscore_at": list(cfg.fscore_at),
                                                        "seed": cfg.seed}, **info}
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "metrics.json", {**extra, **metrics})
    kinds = ", ".join(f"{s}: {v['grid']} grids, {v['mesh']} meshes" for s, v in info["splits"].items())
    write_results(metrics, out, methods=((f"{name} (scored folder)", ""),),
                  intro=f"Predictions of {name} from {args.pred_dir} against {args.data_dir} ({kinds}; "
                        f"grids occupied at >= {cfg.threshold}, meshes in the '{cfg.mesh_frame}' frame).")
    print(f"wrote {out / 'metrics.json'} and {out / 'results.md'}")
    return 0


def _run_targets(args) -> int:
    """``--targets``: pair, read and score every file before anything is written, then write
    metrics.json and results.md as one set (:func:`lit3d.utils.io.write_file_set`)."""
    import json

    from lit3d.utils.io import check_targets, check_writable, write_file_set

    out = Path(args.out)
    check_targets([out / "metrics.json", out / "results.md"], [args.pred_dir, args.targets])
    check_writable(out, "--out")  # before any file is read; creates nothing
    from lit3d.completion.target_pairs import pair_folders
    from lit3d.completion.target_report import conventions, results_text
    from lit3d.completion.target_scores import TargetScoring, score_target_folder

    defaults = evaluation_defaults()
    surface = defaults["surface"]
    cfg = TargetScoring(points=args.points or int(surface["points"]),
                        fscore_at=tuple(args.fscore_at or surface["fscore_at"]), seed=int(surface.get("seed", 0)),
                        threshold=args.threshold, mesh_frame=args.mesh_frame,
                        resolution=args.resolution or int(defaults["folder"]["iou_resolution"]))
    cfg.check()
    pairs, unpaired = pair_folders(args.pred_dir, args.targets)
    if unpaired:
        print(f"{PROG}: note: {len(unpaired)} predictions without a target of their stem, not scored: "
              f"{', '.join(p.name for p in unpaired)}", file=sys.stderr, flush=True)
    rows, means = score_target_folder(pairs, cfg)
    name = args.name or args.pred_dir.resolve().name
    metrics = {"pred_dir": str(args.pred_dir), "target_dir": str(args.targets), "method": name,
               "threshold": cfg.threshold, "mesh_frame": cfg.mesh_frame, "iou_resolution": cfg.resolution,
               "surface": {"points": cfg.points, "fscore_at": list(cfg.fscore_at), "seed": cfg.seed},
               "conventions": conventions(cfg), "unpaired_predictions": [p.name for p in unpaired],
               "pairs": len(rows), "means": means, "items": rows}
    text = results_text(name, str(args.pred_dir), str(args.targets), rows, means, cfg, [p.name for p in unpaired])
    write_file_set(out, {"results.md": text.encode("utf-8"),  # metrics.json last: its presence means a whole set
                         "metrics.json": (json.dumps(metrics, indent=2, allow_nan=False) + "\n").encode("utf-8")},
                   protected=[args.pred_dir, args.targets])
    print(f"wrote {out / 'metrics.json'} and {out / 'results.md'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
