"""Every config composes; every experiment instantiates its task (meta device) and data module."""
from pathlib import Path

import pytest
import torch
from lightning.pytorch import LightningModule
from omegaconf import OmegaConf

from lit3d.runtime.build import build_datamodule, build_task
from lit3d.runtime.compose import CONF_DIR

EXPERIMENTS = sorted(p.stem for p in (Path(CONF_DIR) / "experiment").glob("*.yaml"))
TRAINERS = sorted(p.stem for p in (Path(CONF_DIR) / "trainer").glob("*.yaml"))
LOGGERS = sorted(p.stem for p in (Path(CONF_DIR) / "logger").glob("*.yaml"))


def test_there_are_experiments():
    assert {"completion_demo", "completion_paper"} <= set(EXPERIMENTS)


@pytest.mark.parametrize("name", EXPERIMENTS)
def test_experiment_composes_and_instantiates(compose_cfg, name):
    cfg = compose_cfg([f"experiment={name}"])
    if OmegaConf.is_missing(cfg.data, "root"):  # real-data experiments need data.root
        cfg.data.root = "/path/to/dataset"
    OmegaConf.resolve(cfg.task)
    assert cfg.task_info.name in name
    assert cfg.task_info.monitor and cfg.task_info.monitor_mode in ("min", "max")
    with torch.device("meta"):
        task = build_task(cfg.task)
    assert isinstance(task, LightningModule)
    assert type(task).__module__ == cfg.task._target_.rsplit(".", 1)[0]
    dm = build_datamodule(cfg.data)
    assert hasattr(dm, "describe") and hasattr(dm, "show")


@pytest.mark.parametrize("trainer", TRAINERS)
def test_trainer_presets_compose(compose_cfg, trainer):
    cfg = compose_cfg([f"trainer={trainer}"])
    assert cfg.trainer._target_ == "lightning.pytorch.Trainer"
    if trainer == "ddp_cpu":
        assert cfg.trainer.devices == 2 and cfg.trainer.strategy.process_group_backend == "gloo"
    if trainer == "fdr":
        assert cfg.trainer.fast_dev_run


@pytest.mark.parametrize("logger", LOGGERS)
def test_logger_presets_compose(compose_cfg, logger):
    cfg = compose_cfg([f"logger={logger}"])
    if logger == "wandb":
        assert cfg.logger.wandb.mode == "offline"


def test_data_follows_task_unless_given(compose_cfg):
    assert compose_cfg([]).data._target_.startswith("datamodules.completion")
    cfg = compose_cfg(["data=recgan", "data.root=/somewhere"])
    assert cfg.data.source == "recgan" and cfg.data.root == "/somewhere"


def test_eval_config_requires_ckpt(compose_cfg):
    cfg = compose_cfg(["ckpt_path=x.ckpt"], config_name="eval")
    assert cfg.ckpt_path == "x.ckpt" and cfg.get("data") is None and cfg.get("task") is None
