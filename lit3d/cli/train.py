"""``lit3d-train``: fit a task, test the best checkpoint, write metrics.json.

    lit3d-train experiment=completion_demo
    lit3d-train experiment=completion_demo debug=fdr
    lit3d-train hydra.run.dir=logs/completion/runs/X ckpt_path=last     # resume
    lit3d-train -m +sweep=completion_k                                  # ablation sweep

Returns the monitored metric (``task_info.monitor``) so Hydra sweepers can optimise it.
"""
from __future__ import annotations

import logging
import os
import uuid
import warnings
from pathlib import Path

import hydra
from hydra.utils import instantiate
from omegaconf import DictConfig, OmegaConf

from lit3d.cli.common import cli_main, run_cli
from lit3d.cli.evaluation import run_evaluation, scalar_metrics
from lit3d.runtime.build import build_datamodule, build_task, task_meta, to_plain
from lit3d.runtime.checkpoints import read_checkpoint
from lit3d.runtime.compose import CONF_DIR
from lit3d.runtime.errors import Interrupted, UserError
from lit3d.runtime.extra_checks import check_logger_extras
from lit3d.cli.resume_checks import check_resume_config, check_weights_fit
from lit3d.cli.run_log import with_csv_logger, write_run_curves
from lit3d.cli.stops import preparing, testing_after_fit
from lit3d.utils import forced_exit
from lit3d.utils.io import atomic_write_text, write_json
from lit3d.utils.log_images import WANDB, logger_kind
from lit3d.utils.provenance import provenance

log = logging.getLogger("lit3d")

# torch and Lightning are imported inside train(): a bad command line is answered in about a second


def resolve_ckpt_path(ckpt_path: str | None, output_dir: Path) -> str | None:
    """``None`` -> None; ``last`` -> <run dir>/checkpoints/last.ckpt; else the given path."""
    if ckpt_path in (None, "", "null"):
        return None
    if ckpt_path == "last":
        last = output_dir / "checkpoints" / "last.ckpt"
        if not last.is_file():
            raise UserError(
                f"{last}: no last checkpoint to resume; set hydra.run.dir=<the run dir to resume> "
                "or ckpt_path=<path/to/file.ckpt>"
            )
        return str(last)
    if not Path(ckpt_path).is_file():
        raise UserError(f"{ckpt_path}: checkpoint not found (ckpt_path)")
    return str(ckpt_path)


def build_loggers(cfg: DictConfig, wandb_id: str) -> list:
    """Instantiate the configured loggers; a W&B logger gets a stable run id (resumable)."""
    loggers = []
    for name, lg_cfg in (cfg.get("logger") or {}).items():
        if lg_cfg is None:
            continue
        if "WandbLogger" in str(lg_cfg.get("_target_", "")):
            os.environ.setdefault("WANDB_SILENT", "true")
            logger = instantiate(lg_cfg, id=wandb_id, resume="allow")
            # Lightning's WandbLogger always hands wandb.init `anonymous=None`, which W&B (>= 0.19)
            # answers with "The anonymous setting has no effect"; left out, the run is the same
            getattr(logger, "_wandb_init", {}).pop("anonymous", None)
            loggers.append(logger)
        else:
            loggers.append(instantiate(lg_cfg))
    return loggers


def finish_wandb(loggers: list) -> None:
    """Close W&B runs (also on errors) so multirun jobs do not share a run."""
    for lg in loggers:
        if logger_kind(lg) == WANDB:
            try:
                import wandb

                wandb.finish()
            except Exception:  # pragma: no cover - best effort on shutdown
                pass


def checkpoint_plugins(trainer_cfg: DictConfig) -> dict:
    """``plugins=[AtomicCheckpointIO()]`` unless the trainer config sets its own plugins."""
    if trainer_cfg.get("plugins") is not None:
        return {}
    from lit3d.callbacks.resume import AtomicCheckpointIO

    return {"plugins": [AtomicCheckpointIO()]}


def prepare(trainer, datamodule) -> None:
    """The data preparation, before ``trainer.fit`` (where Lightning's call then finds the data ready).

    Inside ``trainer.fit`` a Ctrl-C was lost: :func:`fit`'s handler raises Lightning's SIGTERM flag,
    which Lightning resets when training starts, so the run trained every epoch and then printed a
    resume line. Here Ctrl-C or SIGTERM stops the preparation at the next item
    (:func:`lit3d.cli.stops.preparing`: exit 143, one line, the finished items kept), before anything
    is trained. On the local rank 0 of each node only, as Lightning does.
    """
    if trainer.local_rank == 0:
        with preparing(datamodule.data_dir):
            datamodule.prepare_data()


def fit(trainer, task, datamodule, ckpt_path: str | None, output_dir: Path) -> None:
    """:func:`prepare`, then ``trainer.fit``; SIGTERM or
    Ctrl-C (SIGINT) becomes :class:`Interrupted` after ``last.ckpt`` is saved.

    Lightning stops on SIGTERM after the current batch (``SIGTERMException``; ``ResumeState`` saves
    ``last.ckpt``). Ctrl-C is made to take the same path: the first SIGINT only raises Lightning's
    SIGTERM flag (instead of its own KeyboardInterrupt handling, which exits 1 with no resume line);
    a second Ctrl-C stops at once (:func:`lit3d.utils.forced_exit.now`: exit 130, one line; a
    checkpoint being written is not kept, the last one saved is).
    """
    import signal
    import threading

    from lightning.pytorch.utilities.exceptions import SIGTERMException

    got: list[str] = []

    def on_sigint(signum, frame):
        if got:  # a second Ctrl-C: stop now
            forced_exit.now(signum)
            raise KeyboardInterrupt  # outside a command's watching scope
        got.append("SIGINT (Ctrl-C)")
        trainer._signal_connector.received_sigterm = True  # Lightning's SIGTERM flag

    prepare(trainer, datamodule)  # Ctrl-C here: one line, nothing trained (lit3d.cli.stops)
    main_thread = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGINT, on_sigint) if main_thread else None
    try:
        with warnings.catch_warnings(), forced_exit.advice(
                f"the last saved checkpoints are kept: resume with the same overrides plus hydra.run.dir={output_dir} "
                "ckpt_path=last"):
            if ckpt_path is not None:  # a resumed run writes into its own checkpoints/ on purpose
                warnings.filterwarnings("ignore", message=r"Checkpoint directory .* exists and is not empty")
            trainer.fit(task, datamodule=datamodule, ckpt_path=ckpt_path, weights_only=True)
    except SIGTERMException as exc:
        raise Interrupted(_stopped(got[0] if got else "SIGTERM", trainer, output_dir)) from exc
    finally:
        if main_thread:
            signal.signal(signal.SIGINT, previous)
    if got:  # Ctrl-C after the last batch: fitting ended, but the user asked to stop before testing
        raise Interrupted(_stopped(got[0], trainer, output_dir))


def _stopped(what: str, trainer, output_dir: Path) -> str:
    return (f"{output_dir}: stopped by {what} at epoch {trainer.current_epoch}; resume with the same "
            f"overrides plus hydra.run.dir={output_dir} ckpt_path=last")


def check_training_length(trainer_cfg: DictConfig) -> None:
    """Refuse ``trainer.max_epochs=0`` / ``trainer.max_steps=0``: nothing would be trained, and the
    test results written afterwards would be those of untrained weights."""
    for key in ("max_epochs", "max_steps"):
        value = trainer_cfg.get(key)
        if value is not None and int(value) == 0:
            raise UserError(f"trainer.{key}=0: nothing would be trained (the test results would be of untrained "
                            "weights); give a positive number, or test a checkpoint with lit3d-eval ckpt_path=...")


def train(cfg: DictConfig) -> float | None:
    """Fit, then test the best checkpoint. Returns the monitored metric value."""
    import lightning.pytorch as pl
    import torch

    from lit3d.callbacks.metadata import MetadataCallback
    from lit3d.callbacks.stop_points import StopPoints

    check_training_length(cfg.trainer)
    check_logger_extras(cfg)  # a multirun job's loggers (a single run's are checked before Hydra starts)
    output_dir = Path(cfg.paths.output_dir)
    output_dir.mkdir(parents=True, exist_ok=True)
    pl.seed_everything(cfg.seed, workers=True)
    torch.set_float32_matmul_precision(cfg.matmul_precision)
    ckpt_path = resolve_ckpt_path(cfg.get("ckpt_path"), output_dir)
    ckpt, meta = read_checkpoint(ckpt_path) if ckpt_path else ({}, {})  # read once for every check below
    if ckpt_path:  # its task, data and architecture against this config (lit3d.cli.resume_checks)
        check_resume_config(ckpt_path, meta, cfg, output_dir)
    wandb_id = meta.get("wandb_id") or uuid.uuid4().hex[:8]

    datamodule = build_datamodule(cfg.data)
    task = build_task(cfg.task)
    if ckpt_path:  # before the data is prepared: weights of another size are one line, not Lightning's traceback
        check_weights_fit(ckpt_path, task, ckpt.get("state_dict") or {})
    del ckpt  # Lightning reads the checkpoint itself to resume
    atomic_write_text(output_dir / "config.yaml", OmegaConf.to_yaml(cfg, resolve=True))  # once every check passed
    loggers = with_csv_logger(build_loggers(cfg, wandb_id), output_dir)  # the CSV log is always on (curves.png)
    callbacks = [instantiate(c) for c in (cfg.get("callbacks") or {}).values() if c is not None]
    settings = to_plain(cfg.get("evaluation"))  # the evaluator's settings, saved in every checkpoint
    callbacks += [MetadataCallback(task_meta(cfg), to_plain(cfg.data), wandb_id, settings),
                  StopPoints()]  # StopPoints: the test's
    trainer: pl.Trainer = instantiate(cfg.trainer, callbacks=callbacks, logger=loggers or False,
                                      **checkpoint_plugins(cfg.trainer))
    for lg in loggers:
        lg.log_hyperparams(to_plain(cfg))
    try:
        fit(trainer, task, datamodule, ckpt_path, output_dir)
        fit_metrics = scalar_metrics(trainer.callback_metrics)
        monitored = _monitored_value(trainer, cfg.task_info.monitor, fit_metrics)
        run_info = {"monitor": cfg.task_info.monitor, "monitored_value": monitored,
                    "provenance": provenance(datamodule)}  # lit3d version, git commit, data manifest hash
        if cfg.get("test_after_fit", True):
            best = trainer.checkpoint_callback.best_model_path if trainer.checkpoint_callback else ""
            with testing_after_fit(output_dir, best or str(output_dir / "checkpoints" / "last.ckpt")):
                log.info("testing %s", best or "the last weights")
                run_evaluation(trainer, task, datamodule, cfg.task_info.name, output_dir, ckpt_path=best or None,
                               n_figures=int(cfg.get("n_figures", 0)), extra=run_info, settings=settings,
                               measured=tested_validation(trainer, cfg.task_info.monitor, fit_metrics))
        elif trainer.is_global_zero:
            write_json(output_dir / "metrics.json", run_info)
        if trainer.is_global_zero:
            write_run_curves(loggers, output_dir, f"{cfg.task_info.name} learning curves: {output_dir}")
        return monitored
    finally:
        finish_wandb(loggers)


def tested_validation(trainer, monitor: str, metrics: dict[str, float]) -> dict[str, float]:
    """The validation numbers of the weights that the test after fitting loads: the best checkpoint's
    monitored value (``{monitor: best score}``, when the monitor is a ``val/`` metric), or, with no best
    checkpoint, the last validation's ``val/`` entries of ``metrics`` (those of the last weights)."""
    cb = trainer.checkpoint_callback
    if cb is not None and cb.best_model_path and cb.best_model_score is not None:
        return {monitor: float(cb.best_model_score)} if monitor.startswith("val/") else {}
    return {k: float(v) for k, v in metrics.items() if k.startswith("val/")}


def _monitored_value(trainer, monitor: str, metrics: dict[str, float]) -> float | None:
    cb = trainer.checkpoint_callback
    if cb is not None and cb.best_model_score is not None:
        return float(cb.best_model_score)
    return metrics.get(monitor)


@hydra.main(version_base="1.3", config_path=CONF_DIR, config_name="train")
def hydra_main(cfg: DictConfig) -> float | None:
    return run_cli(train, cfg)


def main() -> None:
    """Console script ``lit3d-train`` (``--debug``: tracebacks instead of one-line errors)."""
    cli_main(hydra_main)


if __name__ == "__main__":
    main()
