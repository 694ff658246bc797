"""Evaluation settings have their own config node, saved in the checkpoint.

- ``lit3d-train`` hands ``cfg.evaluation`` to the evaluator and saves it in every checkpoint;
  ``lit3d-eval`` of that checkpoint evaluates with it, the command line's ``evaluation.*`` winning;
- a checkpoint saved before the node (the settings among its task's hyper-parameters) loads and
  evaluates with those settings;
- a command line that still sets a moved key under ``task.`` ends with one line naming the new key.
"""
from __future__ import annotations

from pathlib import Path

import pytest
import torch
from omegaconf import open_dict

from lit3d.canonical import evaluator as canonical_evaluator
from lit3d.canonical.module import EVALUATION_LEGACY, CanonicalTask
from lit3d.runtime import eval_settings
from lit3d.cli.common import EXIT_USER, cli_main
from lit3d.runtime.compose import check_composes, compose_config
from lit3d.runtime.errors import UserError
from lit3d.cli.evaluate import evaluate
from lit3d.cli.train import train
from lit3d.completion.module import CompletionTask
from lit3d.quality.module import QualityTask
from lit3d.utils.checkpoints import META_KEY
from lit3d.utils.evaluation import Evaluation

pytestmark = pytest.mark.usefixtures("one_torch_thread")

TINY = ["experiment=canonical_tiny", "debug=limit", "trainer.max_epochs=1", "trainer.limit_val_batches=1",
        "trainer.limit_test_batches=1", "trainer.log_every_n_steps=1", "logger=none", "callbacks.progress_bar=null",
        "callbacks.training_health=null", "evaluation.chance_trials=7", "evaluation.mesh_baselines=[posed]"]


@pytest.fixture
def recorded(monkeypatch) -> list[dict]:
    """The settings each call of the canonical evaluator's protocol got (it scores nothing here)."""
    calls: list[dict] = []

    def protocol(task, datamodule, settings):
        calls.append(dict(settings))
        return Evaluation()

    monkeypatch.setattr(canonical_evaluator, "protocol", protocol)
    return calls


@pytest.fixture(scope="module")
def trained(tmp_path_factory) -> tuple[Path, list[dict]]:
    """One tiny canonical lit3d-train run: (last.ckpt, the settings its test after fitting evaluated with)."""
    from hydra.core.global_hydra import GlobalHydra

    root = tmp_path_factory.mktemp("evaluation_settings")
    cfg = compose_config("train", TINY)
    with open_dict(cfg):
        cfg.paths.output_dir, cfg.paths.data_dir = str(root / "run"), str(root / "data")
    calls: list[dict] = []
    saved, threads = canonical_evaluator.protocol, torch.get_num_threads()
    canonical_evaluator.protocol = lambda task, dm, settings: calls.append(dict(settings)) or Evaluation()
    torch.set_num_threads(1)
    try:
        train(cfg)
    finally:
        canonical_evaluator.protocol = saved
        torch.set_num_threads(threads)
        GlobalHydra.instance().clear()
    return root / "run" / "checkpoints" / "last.ckpt", calls


def _eval_cfg(ckpt: Path, out: Path, *overrides: str):
    """``lit3d-eval`` config with its ``hydra`` node (the command line's overrides as Hydra records them)."""
    cfg = compose_config("eval", [f"ckpt_path={ckpt}", "n_figures=0", *overrides], return_hydra_config=True)
    with open_dict(cfg):
        cfg.paths.output_dir = str(out)
    return cfg


def test_training_saves_the_node_and_evaluation_reads_it_back(trained, recorded, tmp_path, caplog):
    ckpt, at_fit = trained
    assert at_fit and at_fit[0]["chance_trials"] == 7 and at_fit[0]["mesh_baselines"] == ["posed"]
    saved = torch.load(ckpt, map_location="cpu", weights_only=True)
    assert saved[META_KEY]["evaluation"] == at_fit[0]  # the resolved node, in the checkpoint's metadata
    assert "chance_trials" not in saved["hyper_parameters"] and "retrieval" not in saved[META_KEY]["task"]
    with caplog.at_level("INFO", logger="lit3d"):
        evaluate(_eval_cfg(ckpt, tmp_path / "eval"))
    assert recorded == [at_fit[0]]
    assert "evaluation settings: the checkpoint's (saved by lit3d-train)" in caplog.text
    assert "evaluation:" in (tmp_path / "eval" / "config.yaml").read_text()


def test_the_command_line_wins_over_the_checkpoint(trained, recorded, tmp_path, caplog):
    ckpt, at_fit = trained
    with caplog.at_level("INFO", logger="lit3d"):
        evaluate(_eval_cfg(ckpt, tmp_path / "eval", "task=canonical", "evaluation.chance_trials=3",
                           "evaluation.retrieval.vocab=5"))
    got = recorded[0]
    assert got["chance_trials"] == 3 and got["retrieval"]["vocab"] == 5
    # the rest is the checkpoint's, not conf/task/canonical.yaml's (which task=canonical also brings)
    assert got["mesh_baselines"] == ["posed"] and got["retrieval"]["view_size"] == at_fit[0]["retrieval"]["view_size"]
    lines = [r.getMessage() for r in caplog.records if r.getMessage().startswith("evaluation settings")]
    assert len(lines) == 1 and "evaluation.chance_trials, evaluation.retrieval.vocab from the command line" in lines[0]


def test_a_checkpoint_from_before_the_node_evaluates_with_its_task_hparams(trained, recorded, tmp_path, caplog):
    ckpt, _ = trained
    old = torch.load(ckpt, map_location="cpu", weights_only=True)
    del old[META_KEY]["evaluation"]  # as lit3d-train wrote checkpoints before that change
    legacy = {"retrieval": None, "chance_trials": 11, "mesh_baselines": ["cmds"], "baseline_max_vertices": 500}
    old["hyper_parameters"].update(legacy)
    old[META_KEY]["task"].update(legacy)
    path = tmp_path / "old.ckpt"
    torch.save(old, path)
    task = CanonicalTask.load_from_checkpoint(path, map_location="cpu", weights_only=True)  # the old keys are accepted
    assert "chance_trials" not in task.hparams
    with caplog.at_level("INFO", logger="lit3d"):
        evaluate(_eval_cfg(path, tmp_path / "eval"))
    assert recorded == [{**EVALUATION_LEGACY, **legacy}]  # keys it lacks: the constructor's defaults then
    assert "task hyper-parameters" in caplog.text
    with pytest.raises(TypeError, match="unexpected keyword argument 'retreival'"):
        CanonicalTask(net=old["hyper_parameters"]["net"], retreival=None)  # a misspelt key is still an error


def test_legacy_settings_of_the_other_tasks():
    surface = {"points": 100, "fscore_at": [0.01], "seed": 0}
    settings, where = eval_settings.checkpoint_settings({"hyper_parameters": {"nets": {}, "surface": surface}}, {},
                                                        CompletionTask)
    assert settings == {"surface": surface} and "hyper-parameters" in where
    settings, _ = eval_settings.checkpoint_settings({}, {"task": {"cv": True, "cv_epochs": 3}}, QualityTask)
    assert settings["cv"] is True and settings["cv_epochs"] == 3 and settings["cv_methods"] == ("ours_all", "ours_sfs")
    assert "cv" not in QualityTask(cv=True, cross_data=None).hparams  # old checkpoints' keys: accepted, not kept
    saved = {"surface": None}
    assert eval_settings.checkpoint_settings({}, {"evaluation": saved}, CompletionTask)[0] == saved


def test_command_line_keys_and_their_values():
    keys = eval_settings.command_line_keys(["task=canonical", "evaluation.retrieval.vocab=300", "+evaluation.x=1",
                                            "~evaluation.mesh_baselines", "data.root=x"])
    assert keys == ["retrieval.vocab", "x", "mesh_baselines"]
    base = {"retrieval": {"vocab": 1000, "level": 2}, "mesh_baselines": ["cmds"], "chance_trials": 100}
    given = {"retrieval": {"vocab": 300, "level": 0}, "x": 1, "chance_trials": 5}
    assert eval_settings.with_command_line(base, given, keys) == {"retrieval": {"vocab": 300, "level": 2},
                                                                  "chance_trials": 100, "x": 1}


@pytest.mark.parametrize("args, line", [
    (["experiment=canonical_tiny", "task.mesh_baselines=[]"], "task.mesh_baselines: an evaluation setting now"),
    (["experiment=canonical_tiny", "task.retrieval.vocab=300"], "set evaluation.retrieval.vocab=..."),
    (["experiment=canonical_tiny", "+task.chance_trials=3"], "set evaluation.chance_trials=..."),
    (["experiment=quality_demo", "task.cv=false"], "set evaluation.cv=..."),
    (["experiment=completion_demo", "task.surface=null"], "set evaluation.surface=..."),
])
def test_an_old_task_key_is_one_line_naming_the_new_one(args, line):
    with pytest.raises(UserError, match=line.replace(".", r"\.").replace("[", r"\[")):
        check_composes(args, "train")


def test_the_old_key_ends_the_command_with_one_line(capsys):
    with pytest.raises(SystemExit) as stop:
        cli_main(lambda: None, ["experiment=canonical_tiny", "task.mesh_baselines=[]"])
    err = capsys.readouterr().err.strip().splitlines()
    assert stop.value.code == EXIT_USER and len(err) == 1 and "evaluation.mesh_baselines" in err[0], err
    with pytest.raises(UserError, match="task=canonical"):  # lit3d-eval: the node comes with task=NAME
        check_composes(["ckpt_path=x.ckpt", "evaluation.chance_trials=3"], "eval")
    assert check_composes(["ckpt_path=x.ckpt", "task=canonical", "evaluation.chance_trials=3"],
                          "eval").evaluation.chance_trials == 3
