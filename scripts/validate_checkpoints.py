"""Score training checkpoints on their run's validation split, with the task's validation metrics.

    python scripts/validate_checkpoints.py RUN/checkpoints/best-011.ckpt OTHER_RUN/checkpoints/last.ckpt \\
        --all-val --out val.json

Each checkpoint's run folder (``RUN/config.yaml``, written by lit3d-train) gives the data; the task is
loaded from the checkpoint. ``--all-val``: every validation item (``data.max_val_items=null``), not the
training run's subset. Prints one JSON line per checkpoint (``val/...`` metrics, e.g. the canonical
task's ``val/retrieval_nn``: validation subjects retrieved by mask IoU) and writes them all to ``--out``.
Use it to compare settings on people never tested (issue 33) with checkpoints trained before a metric
existed.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import lightning.pytorch as pl
from omegaconf import OmegaConf

from lit3d.cli.common import build_datamodule, import_object


def validate(ckpt: Path, all_val: bool) -> dict[str, float]:
    """``{metric: value}`` of ``ckpt`` on the validation split of its run's data config."""
    cfg = OmegaConf.load(ckpt.parent.parent / "config.yaml")
    if all_val and "max_val_items" in cfg.data:
        cfg.data.max_val_items = None
    dm = build_datamodule(cfg.data)
    task = import_object(cfg.task._target_).load_from_checkpoint(str(ckpt), map_location="cpu")
    trainer = pl.Trainer(logger=False, enable_progress_bar=False, enable_model_summary=False, accelerator="cpu")
    return {k: round(float(v), 4) for k, v in trainer.validate(task, dm, verbose=False)[0].items()}


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("ckpts", nargs="+", type=Path, help="checkpoints RUN/checkpoints/NAME.ckpt")
    p.add_argument("--all-val", action="store_true", help="every validation item, not the run's subset")
    p.add_argument("--out", type=Path, help="write {checkpoint: metrics} here (JSON)")
    args = p.parse_args(argv)
    rows = {}
    for ckpt in args.ckpts:
        rows[str(ckpt)] = validate(ckpt, args.all_val)
        print(ckpt, json.dumps(rows[str(ckpt)]), flush=True)
    if args.out:
        args.out.write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
