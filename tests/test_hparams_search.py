"""hparams_search=<task>_optuna (Hydra's Optuna sweeper) and callbacks=early_stopping."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
import yaml
from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra
from hydra.utils import instantiate
from omegaconf import OmegaConf

from lit3d.cli.common import CONF_DIR

REPO = Path(__file__).resolve().parents[1]


def _compose(overrides: list[str]):
    GlobalHydra.instance().clear()
    try:
        with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
            return compose("train", overrides=overrides, return_hydra_config=True)
    finally:
        GlobalHydra.instance().clear()


@pytest.mark.parametrize("search, experiment, direction", [
    ("completion_optuna", "completion_demo", "maximize"),   # val/iou, mode max
    ("canonical_optuna", "canonical_tiny", "minimize"),     # val/depth_mse, mode min
])
def test_optuna_direction_follows_the_monitored_metric(search, experiment, direction):
    cfg = _compose([f"hparams_search={search}", f"experiment={experiment}"])
    sweeper = cfg.hydra.sweeper
    assert sweeper._target_.endswith("OptunaSweeper") and sweeper.direction == direction
    assert cfg.hydra.mode.name == "MULTIRUN"
    for key in sweeper.params:  # every searched key is a key of the composed config
        assert OmegaConf.select(cfg, key) is not None, key
    flipped = "min" if cfg.task_info.monitor_mode == "max" else "max"
    assert _compose([f"hparams_search={search}", f"experiment={experiment}",
                     f"task_info.monitor_mode={flipped}"]).hydra.sweeper.direction == f"{flipped}imize"


def test_early_stopping_is_off_by_default_and_watches_the_monitor():
    from lightning.pytorch.callbacks import EarlyStopping

    assert "early_stopping" not in _compose(["experiment=completion_demo"]).callbacks
    cfg = _compose(["experiment=completion_demo", "callbacks=early_stopping", "callbacks.early_stopping.patience=3"])
    assert {"model_checkpoint", "resume_state"} <= set(cfg.callbacks)  # the default callbacks stay
    stop = instantiate(cfg.callbacks.early_stopping)
    assert isinstance(stop, EarlyStopping) and stop.monitor == "val/iou" and stop.mode == "max" and stop.patience == 3


def test_two_optuna_trials_of_a_tiny_config(tmp_path):
    sweep = tmp_path / "sweep"
    env = {**os.environ, "OMP_NUM_THREADS": "1", "HYDRA_FULL_ERROR": "1", "WANDB_MODE": "offline"}
    args = [str(Path(sys.executable).parent / "lit3d-train"), "hparams_search=canonical_optuna",
            "experiment=canonical_tiny", "debug=limit", "trainer.max_epochs=1", "test_after_fit=false",
            "logger=none", "callbacks.progress_bar=null", "evaluation.retrieval=null", "hydra.sweeper.n_trials=2",
            f"hydra.sweep.dir={sweep}", f"paths.data_dir={tmp_path / 'data'}"]
    res = subprocess.run(args, cwd=REPO, env=env, capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr[-3000:]
    best = yaml.safe_load((sweep / "optimization_results.yaml").read_text())
    trials = [json.loads((sweep / str(i) / "metrics.json").read_text()) for i in range(2)]
    assert all(t["monitor"] == "val/depth_mse" for t in trials)
    assert best["best_value"] == pytest.approx(min(t["monitored_value"] for t in trials))  # minimised
    assert set(best["best_params"]) == {"task.lr", "task.net.warp_hidden"}
    lrs = {next(o for o in yaml.safe_load((sweep / str(i) / ".hydra" / "overrides.yaml").read_text())
                if o.startswith("task.lr=")) for i in range(2)}
    assert len(lrs) == 2  # the sampler proposed two settings
    assert all((sweep / str(i) / "curves.png").is_file() for i in range(2))
