"""Score training checkpoints on their run's validation split, with the task's validation metrics.

    python -m studies.canonical.validate_checkpoints RUN/checkpoints/best-011.ckpt OTHER_RUN/checkpoints/last.ckpt \\
        --all-val --out val.json [--heldout DIR]

Each checkpoint's run folder (``RUN/config.yaml``, written by lit3d-train) gives the data; the task is
loaded from the checkpoint. ``--all-val``: every validation item (``data.split.max_val_items=null``), not the
training run's subset. Prints one JSON line per checkpoint (``val/...`` metrics, e.g. the canonical
task's ``val/retrieval_nn``: validation subjects retrieved by mask IoU) and writes them all to ``--out``.
Use it to compare settings on people never tested with checkpoints trained before a metric
existed. One checkpoint's ``val/`` metrics without ``--heldout`` are also ``lit3d-eval ckpt_path=CKPT split=val
data.split.max_val_items=null`` (its metrics.json; that reads the data config from the checkpoint).

``--heldout DIR`` (canonical task): also writes the validation items' predictions as
``DIR/<i>/heldout.npz`` (``i``: the checkpoint's place on the command line), as ``lit3d-eval ckpt_path=CKPT
split=val`` writes them into its run dir, so that ``lit3d-summary --pooled DIR/<i> --out ...`` ranks settings on
validation people with the thesis descriptor, the measure the test reports, instead of on the test set.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import lightning.pytorch as pl
from omegaconf import OmegaConf

from datamodules.canonical.flat_config import upgrade_data_config
from lit3d.canonical.evaluator import validation_protocol, write_artefacts
from lit3d.runtime.build import build_datamodule, import_object
from lit3d.runtime.checkpoints import read_checkpoint
from lit3d.runtime.eval_settings import checkpoint_settings


def _trainer() -> pl.Trainer:
    return pl.Trainer(logger=False, enable_progress_bar=False, enable_model_summary=False, accelerator="cpu")


def validate(ckpt: Path, all_val: bool, heldout: Path | None = None) -> dict[str, float]:
    """``{metric: value}`` of ``ckpt`` on the validation split of its run's data config; with ``heldout``
    (a folder) the validation predictions are written there as ``heldout.npz``."""
    config = ckpt.parent.parent / "config.yaml"
    cfg = OmegaConf.load(config)
    data = upgrade_data_config(OmegaConf.to_container(cfg.data, resolve=True), str(config))  # either layout
    if all_val:
        data["split"] = {**(data.get("split") or {}), "max_val_items": None}
    dm = build_datamodule(data)
    task_cls = import_object(cfg.task._target_)
    hparams = read_checkpoint(ckpt)[0]["hyper_parameters"]  # in today's layout
    task = task_cls.load_from_checkpoint(str(ckpt), map_location="cpu", **hparams)
    metrics = {k: round(float(v), 4) for k, v in _trainer().validate(task, dm, verbose=False)[0].items()}
    if heldout is not None:
        write_validation_heldout(task, dm, ckpt, task_cls, heldout)
    return metrics


def write_validation_heldout(task, dm, ckpt: Path, task_cls, folder: Path) -> list[Path]:
    """The validation items' predictions saved as ``folder/heldout.npz``, as ``lit3d-eval split=val`` saves
    them (:func:`lit3d.canonical.evaluator.validation_protocol`, the checkpoint's evaluation settings)."""
    ck, meta = read_checkpoint(ckpt)
    settings, _ = checkpoint_settings(ck, meta, task_cls)
    folder.mkdir(parents=True, exist_ok=True)
    return write_artefacts(validation_protocol(_trainer(), task, dm, settings), folder)


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("ckpts", nargs="+", type=Path, help="checkpoints RUN/checkpoints/NAME.ckpt")
    p.add_argument("--all-val", action="store_true", help="every validation item, not the run's subset")
    p.add_argument("--out", type=Path, help="write {checkpoint: metrics} here (JSON)")
    p.add_argument("--heldout", type=Path, help="write each checkpoint's validation predictions to HELDOUT/<i>/")
    args = p.parse_args(argv)
    rows = {}
    for i, ckpt in enumerate(args.ckpts):
        rows[str(ckpt)] = validate(ckpt, args.all_val, args.heldout / str(i) if args.heldout else None)
        print(ckpt, json.dumps(rows[str(ckpt)]), flush=True)
    if args.out:
        args.out.write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
