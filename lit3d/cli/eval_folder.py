"""``lit3d-eval-folder PRED_DIR DATA_DIR --out OUT``: score another method's shape completions
against the targets of a prepared completion data split, with lit3d's test metrics.

Examples::

    lit3d-eval-folder preds/ data/completion_demo_sweethome3d --out eval_other/
    lit3d-eval-folder meshes/ data/completion_synth --out eval_onet/ --mesh-frame unit --name "ONet"
    lit3d-eval-folder grids/ DATA --out OUT --split test_same --threshold 0.4

The prediction of the cached target ``DATA_DIR/items/<split>/<stem>.npz`` is
``PRED_DIR/<split>/<stem>.<ext>`` or ``PRED_DIR/<stem>.<ext>``: a voxel grid (.npz/.npy, the
target's shape, {0, 1} or probabilities in [0, 1]; an SDF under the npz key 'sdf') or a mesh
(.obj/.ply/.off in the grid's frame, see --mesh-frame). Splits with predictions are scored
(every target of a scored split needs one). Writes OUT/metrics.json and OUT/results.md: the
thesis-layout IoU tables (grid predictions) and the surface metrics (Chamfer-L1, F-score,
normal consistency) beside IoU, as lit3d-eval writes them for a checkpoint. Point count, F-score
thresholds and seed default to evaluation.surface of conf/task/completion.yaml. Bad input (a missing,
unreadable or wrongly shaped prediction, no prepared data) ends with one line naming the file
and exit status 2.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from lit3d.cli.about import run_argparse_cli, version_line
from lit3d.runtime.compose import CONF_DIR

PROG = "lit3d-eval-folder"


def surface_defaults() -> dict:
    """``evaluation.surface`` of ``conf/task/completion.yaml`` (points, fscore_at, seed)."""
    from omegaconf import OmegaConf

    return OmegaConf.to_container(OmegaConf.load(Path(CONF_DIR) / "task" / "completion.yaml").evaluation.surface)


def _parser() -> argparse.ArgumentParser:
    doc = __doc__.replace("``", "'")
    p = argparse.ArgumentParser(prog=PROG, description=doc.split("\n\n")[0],
                                epilog="\n\n".join(doc.split("\n\n")[1:]),
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("pred_dir", type=Path, help="folder of predictions (grids .npz/.npy or meshes .obj/.ply/.off)")
    p.add_argument("data_dir", type=Path, help="prepared completion data (lit3d-data; holds manifest.json)")
    p.add_argument("--out", type=Path, required=True, help="folder for metrics.json and results.md")
    p.add_argument("--split", action="append",  # checked against the data's test splits by score_folder
                   help="score only this test split: test_same, test_cross, test_unseen or test_unseen_cross "
                        "(repeatable; default: every split with predictions)")
    p.add_argument("--name", default=None, help="the method's row label in results.md (default: PRED_DIR's name)")
    p.add_argument("--threshold", type=float, default=0.5, help="grid probabilities >= this are occupied (0.5)")
    p.add_argument("--mesh-frame", choices=("unit", "voxel"), default="unit",
                   help="meshes: 'unit' = the target grid is the cube [-0.5, 0.5]^3 (default); "
                        "'voxel' = vertex (x, y, z) at grid index [x, y, z]")
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


def _run(args) -> int:
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


if __name__ == "__main__":
    sys.exit(main())
