"""results.md of a canonical run from its metrics.json, with the U-Net rows of a plain U-Net run merged
(the report itself: :mod:`lit3d.canonical.report`).

    python -m studies.canonical.report RUN_DIR [SOURCE] [--unet UNET_RUN_DIR]
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from lit3d.canonical.report import TABLE_OF_SOURCE, write_results


def unet_run_metrics(unet_metrics: dict) -> dict:
    """The metrics of a plain U-Net run (``task.arch=unet``: its metrics.json) under the U-Net
    rows' keys: ``test/depth_mse|iou`` -> ``test/depth_mse_unet|iou_unet``, its retrieval
    (``test/retrieval/unet/...``; ``.../model/...`` in runs older than the source name) as is."""
    out = {f"{k}_unet": unet_metrics[k] for k in ("test/depth_mse", "test/iou") if k in unet_metrics}
    for key, value in unet_metrics.items():
        for prefix in ("test/retrieval/unet/", "test/retrieval/model/"):
            if key.startswith(prefix):
                out.setdefault("test/retrieval/unet/" + key[len(prefix):], value)
    return out


def main(argv: list[str] | None = None) -> None:
    """``python -m studies.canonical.report RUN_DIR [SOURCE] [--unet UNET_RUN_DIR]``: results.md from a
    run's metrics.json (e.g. after ``lit3d-train``, which writes metrics.json but no report); with
    ``--unet``, the U-Net rows from the metrics.json of a plain U-Net run (``task.arch=unet``, same
    data) are added and RUN_DIR's metrics.json is left as it is."""
    parser = argparse.ArgumentParser(prog="python -m studies.canonical.report")
    parser.add_argument("run", type=Path, help="run dir with metrics.json")
    parser.add_argument("source", nargs="?", default=None, choices=sorted(TABLE_OF_SOURCE))
    parser.add_argument("--unet", type=Path, default=None, help="run dir of a plain U-Net run (task.arch=unet)")
    args = parser.parse_args(sys.argv[1:] if argv is None else argv)
    metrics = json.loads((args.run / "metrics.json").read_text())
    if args.unet is not None:
        metrics.update(unet_run_metrics(json.loads((args.unet / "metrics.json").read_text())))
    print(write_results(metrics, args.run, args.source))


if __name__ == "__main__":
    main()
