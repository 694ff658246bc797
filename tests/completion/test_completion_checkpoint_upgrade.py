"""Completion and quality checkpoints of the flat layout (before the settings became config nodes) read as
today's: the shipped completion-furniture checkpoint carries the old flat hyper-parameters and data config."""
from __future__ import annotations

import copy

import pytest
import torch

from datamodules.completion import CompletionDataModule
from datamodules.quality.flat_config import upgrade_data_config as upgrade_quality_data
from lit3d.completion.checkpoint_upgrade import upgrade_checkpoint, upgrade_hparams
from lit3d.completion.module import CompletionTask
from lit3d.quality.checkpoint_upgrade import upgrade_checkpoint as upgrade_quality
from lit3d.runtime.checkpoints import read_checkpoint
from lit3d.utils.checkpoints import META_KEY, load_checkpoint
from lit3d.zoo import zoo_model
from tests.helpers.completion import tiny_nets

FLAT = {"critic_steps": 2, "lr_g": 1e-3, "lr_d": 2e-4, "betas": [0.5, 0.9],
        "eps": 1e-7, "loss_scale": "voxels", "alpha": 0.3, "gamma": 0.7, "zeta": 0.02, "gp_lambda": 5.0, "gp_every": 4,
        "critic_concat": True, "gp_precision": "bf16", "stage_weight": 0.5, "adversarial": False,
        "adversarial_start_epoch": 6, "image_every_n_epochs": 5, "mesh_every_n_epochs": 3, "prior_samples": 8}


def test_flat_hyper_parameters_move_into_their_nodes(completion_demo_nets):
    up = upgrade_hparams({**FLAT, "surface": {"points": 10}})
    assert up["optimizer"] == {"lr_g": 1e-3, "lr_d": 2e-4, "betas": [0.5, 0.9], "eps": 1e-7, "loss_scale": "voxels"}
    assert up["loss"] == {"alpha": 0.3, "gamma": 0.7, "zeta": 0.02, "stage_weight": 0.5}
    assert up["adversarial"] == {"use": False, "start_epoch": 6, "critic_steps": 2, "gp_lambda": 5.0, "gp_every": 4,
                                 "critic_concat": True, "gp_precision": "bf16"}
    assert up["panels"] == {"image_every_n_epochs": 5, "mesh_every_n_epochs": 3}
    assert "surface" not in up and upgrade_hparams({**FLAT, "surface": None}, keep_evaluation=True)["surface"] is None
    assert upgrade_hparams(up) == up  # today's layout unchanged
    task = CompletionTask(**{**up, "nets": tiny_nets(completion_demo_nets)})
    assert task.adversarial.gp_every == 4 and task.critic is None and task.optimizer_settings.betas == (0.5, 0.9)


def test_old_keys_are_refused_by_the_constructor_and_unknown_node_keys_named(completion_demo_nets):
    nets = tiny_nets(completion_demo_nets)
    with pytest.raises(TypeError, match="unexpected keyword argument"):
        CompletionTask(nets=nets, **FLAT)
    with pytest.raises(ValueError, match=r"task\.adversarial\.gp_evry: not a setting of task\.adversarial"):
        CompletionTask(nets=nets, adversarial={"gp_evry": 2})


def test_the_shipped_checkpoint_is_read_in_todays_layout_and_its_data_config_builds(tmp_path):
    raw = load_checkpoint(zoo_model("completion-furniture").path)
    assert "lr_g" in raw["hyper_parameters"] and "sensor" in raw[META_KEY]["data"]  # the old flat layout
    ckpt = upgrade_checkpoint(copy.deepcopy(raw))
    hp = ckpt["hyper_parameters"]
    assert hp["adversarial"]["use"] is False and hp["optimizer"]["lr_g"] == raw["hyper_parameters"]["lr_g"]
    assert ckpt[META_KEY]["task"]["name"] == "completion" and "panels" in ckpt[META_KEY]["task"]
    data = ckpt[META_KEY]["data"]
    assert data["render"]["sensor"] == "recgan" and data["meshes"]["min_models"] == 8
    assert data["prepare"] == {"workers": 0, "progress": True, "skip_bad": False, "compress": True}
    assert data["categories"] == {"seen": None, "unseen": None}
    dm = CompletionDataModule(**{**{k: v for k, v in data.items() if k != "_target_"}, "data_dir": str(tmp_path)})
    assert dm.sensor.camera == "perspective" and dm.views_per_shape == 4
    # lit3d-eval and a resume read it so, through the one upgrade
    path = tmp_path / "old.ckpt"
    torch.save(raw, path)
    read, meta = read_checkpoint(path)
    assert read["hyper_parameters"] == hp and meta["data"] == data


def test_quality_data_config_and_datamodule_hyper_parameters_are_upgraded():
    flat = {"source": "synth", "shapes": ["blob"], "n_levels": 2, "feature_fn": None, "feature_options": {"size": 32},
            "feature_workers": 2, "test_shapes": None, "val_shapes": [], "groups": "shape", "batch_size": 3}
    nested = upgrade_quality_data(flat)
    assert nested == {"source": "synth", "batch_size": 3, "synth": {"shapes": ["blob"], "n_levels": 2},
                      "feature_tables": {"fn": None, "options": {"size": 32}, "workers": 2},
                      "split": {"test_shapes": None, "val_shapes": [], "groups": "shape"}}
    assert upgrade_quality_data(nested) == nested
    ckpt = {META_KEY: {"task": {"name": "quality"}, "data": dict(flat)}, "datamodule_hyper_parameters": dict(flat)}
    upgrade_quality(ckpt)
    assert ckpt[META_KEY]["data"] == nested and ckpt["datamodule_hyper_parameters"] == nested
    other = {META_KEY: {"task": {"name": "completion"}, "data": dict(flat)}}
    assert upgrade_quality(other)[META_KEY]["data"] == flat  # another task's: unchanged
