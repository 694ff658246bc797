"""``lit3d-eval``: evaluate a checkpoint without training.

    lit3d-eval ckpt_path=logs/completion/runs/X/checkpoints/last.ckpt
    lit3d-eval task=completion ckpt_path=... data=recgan data.root=../shared/data/recgan_sample

Writes into the run dir: metrics.json, results.md (the thesis's table layout,
with the thesis's figures beside ours) and PNG figures. Validation runs first
when the task picks a threshold there (completion), then test.
"""
from __future__ import annotations

from pathlib import Path

import hydra
import lightning.pytorch as pl
import torch
from hydra.utils import instantiate
from omegaconf import DictConfig, OmegaConf

from lit3d.cli.common import (
    CONF_DIR,
    UserError,
    build_datamodule,
    import_object,
    log,
    read_checkpoint_meta,
    run_cli,
    to_plain,
)
from lit3d.cli.train import scalar_metrics
from lit3d.tasks.registry import report_module
from lit3d.utils.io import write_json


def evaluate(cfg: DictConfig) -> dict[str, float]:
    out_dir = Path(cfg.paths.output_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    pl.seed_everything(cfg.seed, workers=True)
    torch.set_float32_matmul_precision(cfg.matmul_precision)
    meta = read_checkpoint_meta(cfg.ckpt_path)
    task_cfg = meta["task"]
    wanted = cfg.get("task")
    if wanted is not None and wanted.get("name") != task_cfg.get("name"):
        raise UserError(
            f"{cfg.ckpt_path}: checkpoint is for task '{task_cfg.get('name')}', not '{wanted.get('name')}'"
        )
    task_cls = import_object(task_cfg["_target_"])
    task = task_cls.load_from_checkpoint(cfg.ckpt_path, map_location="cpu")
    data_cfg = to_plain(cfg.data) if cfg.get("data") is not None else dict(meta["data"])
    if hasattr(task, "adapt_data_config"):
        data_cfg = task.adapt_data_config(data_cfg)
    datamodule = build_datamodule(data_cfg)
    trainer: pl.Trainer = instantiate(cfg.trainer, logger=False, enable_checkpointing=False,
                                      callbacks=[pl.callbacks.RichProgressBar()])
    metrics: dict[str, float] = {}
    if getattr(task, "validate_before_test", False):
        trainer.validate(task, datamodule=datamodule)
        metrics.update({k: v for k, v in scalar_metrics(trainer.callback_metrics).items() if k.startswith("val/")})
    trainer.test(task, datamodule=datamodule)
    metrics.update({k: v for k, v in scalar_metrics(trainer.callback_metrics).items() if k.startswith("test/")})
    if trainer.is_global_zero:
        write_json(out_dir / "metrics.json", {"ckpt_path": str(cfg.ckpt_path), **metrics})
        report = report_module(task_cfg["name"])
        report.write_results(metrics, out_dir)
        figures = report.write_figures(task, datamodule, out_dir, n=cfg.n_figures)
        OmegaConf.save(OmegaConf.create({"task": task_cfg, "data": data_cfg}), out_dir / "config.yaml")
        log.info("wrote %s, results.md and %d figures", out_dir / "metrics.json", len(figures))
    return metrics


@hydra.main(version_base="1.3", config_path=CONF_DIR, config_name="eval")
def main(cfg: DictConfig) -> None:
    run_cli(evaluate, cfg)


if __name__ == "__main__":
    main()
