"""A checkpoint against the config that resumes or evaluates it: the data
and the architecture must be the checkpoint's unless ``+resume.allow_changes=true``, an edited run-dir
``config.yaml`` is refused (not taken, not overwritten), and a checkpoint of another task or another
architecture is one line, exit 2, before any data is prepared.

The checkpoints are those of untrained models (:func:`lit3d.api.checkpoints.untrained_checkpoint`:
the weights, hyper-parameters and lit3d metadata ``lit3d-train`` stores): what the checks read.
``trainer.fit`` and the evaluation are replaced by a stand-in that only records that the run got
that far.
"""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from omegaconf import OmegaConf

import lit3d.cli.evaluate as evaluate_cli
import lit3d.cli.train as train_cli
from lit3d.api.checkpoints import untrained_checkpoint
from lit3d.cli.common import run_cli
from tests.helpers.paths import REPO

TINY = ["experiment=completion_demo", "data.sizes={train:8,val:4,test_same:4,test_cross:4,test_unseen:4}",
        "data.batch_size=4", "task.nets.latent_dim=64", "task.nets.k=16", "task.nets.fixed_latent_dim=64",
        "task.prior_samples=2", "trainer.max_epochs=1", "logger=none"]
CANONICAL = ["experiment=canonical_tiny", "logger=none"]


class Reached(Exception):
    """The run got past every check (to ``trainer.fit`` / the evaluation)."""


@pytest.fixture(autouse=True)
def _no_training(monkeypatch):
    monkeypatch.delenv("HYDRA_FULL_ERROR", raising=False)

    def reached(*args, **kwargs):
        raise Reached

    monkeypatch.setattr(train_cli, "fit", reached)
    monkeypatch.setattr(evaluate_cli, "run_evaluation", reached)


@pytest.fixture(scope="module")
def completion_ckpt(tmp_path_factory):
    """A checkpoint of TINY (data.render.sensor=recgan, latent_dim=64)."""
    return untrained_checkpoint("completion_demo", tmp_path_factory.mktemp("ckpt") / "completion.ckpt", TINY[1:])


@pytest.fixture(scope="module")
def canonical_ckpt(tmp_path_factory):
    return untrained_checkpoint("canonical_tiny", tmp_path_factory.mktemp("ckpt") / "canonical.ckpt", CANONICAL[1:])


def run(fn, cfg, capsys) -> tuple[int | str, list[str]]:
    """``run_cli(fn, cfg)`` -> (exit status or "reached", stderr lines)."""
    try:
        run_cli(fn, cfg)
        code: int | str = 0
    except SystemExit as exc:
        code = exc.code
    except Reached:
        code = "reached"
    return code, [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]


# ------------------------------------------------------------------ fault 11: resume compares configs
def test_changed_data_is_refused_naming_the_keys(completion_ckpt, compose_cfg, capsys, tmp_path):
    cfg = compose_cfg([*TINY, "data.render.sensor=ortho", "data.render.views_per_shape=2", f"ckpt_path={completion_ckpt}"])
    code, lines = run(train_cli.train, cfg, capsys)
    assert code == 2 and len(lines) == 1, lines
    assert lines[0].startswith(f"error: {completion_ckpt}: this run's data or architecture differs"), lines
    assert "data.render.sensor: recgan in the checkpoint, ortho here" in lines[0]
    assert "data.render.views_per_shape: 4 in the checkpoint, 2 here" in lines[0]
    assert "+resume.allow_changes=true" in lines[0]
    assert not (tmp_path / "run" / "config.yaml").exists() and not (tmp_path / "data").exists()


def test_allow_changes_takes_them(completion_ckpt, compose_cfg, capsys, tmp_path):
    cfg = compose_cfg([*TINY, "data.render.sensor=ortho", "+resume.allow_changes=true", f"ckpt_path={completion_ckpt}"])
    code, lines = run(train_cli.train, cfg, capsys)
    assert code == "reached", lines
    assert OmegaConf.load(tmp_path / "run" / "config.yaml").data.render.sensor == "ortho"


def test_run_length_and_learning_rate_may_change(completion_ckpt, compose_cfg, capsys):
    """Not refused: extending a run (trainer.max_epochs) and other task settings (logged) are free."""
    cfg = compose_cfg([*TINY, "trainer.max_epochs=3", "task.optimizer.lr_g=0.01", "data.num_workers=1",
                       f"ckpt_path={completion_ckpt}"])
    code, lines = run(train_cli.train, cfg, capsys)
    assert code == "reached", lines


def test_edited_run_dir_config_is_refused_not_overwritten(completion_ckpt, compose_cfg, capsys, tmp_path):
    """The user edits <run dir>/config.yaml and resumes with the same command line: the edit would be
    neither taken nor kept. Refused, naming the file and the key; the file is left as edited."""
    cfg = compose_cfg([*TINY, f"ckpt_path={completion_ckpt}"])
    edited = OmegaConf.to_container(cfg, resolve=True)
    edited["data"]["render"]["sensor"] = "ortho"
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    (run_dir / "config.yaml").write_text(OmegaConf.to_yaml(OmegaConf.create(edited)))
    before = (run_dir / "config.yaml").read_bytes()
    code, lines = run(train_cli.train, cfg, capsys)
    assert code == 2 and len(lines) == 1, lines
    assert lines[0].startswith(f"error: {run_dir / 'config.yaml'}: edited since the checkpoint was saved"), lines
    assert "data.render.sensor: ortho in config.yaml, recgan in this run" in lines[0]
    assert (run_dir / "config.yaml").read_bytes() == before


# ------------------------------------------------------------------ fault 14: checkpoints that do not fit
def test_train_with_a_checkpoint_of_another_task(canonical_ckpt, compose_cfg, capsys, tmp_path):
    code, lines = run(train_cli.train, compose_cfg([*TINY, f"ckpt_path={canonical_ckpt}"]), capsys)
    assert code == 2 and len(lines) == 1, lines
    assert lines[0].startswith(f"error: {canonical_ckpt}: the checkpoint holds the canonical task "
                               "(lit3d.canonical.module.CanonicalTask), this config the completion task"), lines
    assert not (tmp_path / "data").exists()


def test_resume_with_another_architecture(completion_ckpt, compose_cfg, capsys, tmp_path):
    cfg = compose_cfg([*TINY, "task.nets.latent_dim=32", f"ckpt_path={completion_ckpt}"])
    code, lines = run(train_cli.train, cfg, capsys)
    assert code == 2 and len(lines) == 1 and "task.nets.latent_dim: 64 in the checkpoint, 32 here" in lines[0], lines
    # taken with allow_changes, the weights still have to fit: one line naming a tensor and both shapes
    cfg = compose_cfg([*TINY, "task.nets.latent_dim=32", "+resume.allow_changes=true", f"ckpt_path={completion_ckpt}"])
    code, lines = run(train_cli.train, cfg, capsys)
    assert code == 2 and len(lines) == 1, lines
    assert lines[0].startswith(f"error: {completion_ckpt}: the checkpoint's weights do not fit the nets"), lines
    assert "in the checkpoint" in lines[0] and "here" in lines[0] and "64" in lines[0] and "32" in lines[0]
    assert not (tmp_path / "data").exists()
    assert not (tmp_path / "run" / "config.yaml").exists()  # a refused resume leaves the run dir's config as it was


def test_eval_of_a_canonical_checkpoint_with_completion_data(canonical_ckpt, compose_cfg, capsys, tmp_path):
    cfg = compose_cfg([f"ckpt_path={canonical_ckpt}", "data=completion_synth"], config_name="eval")
    code, lines = run(evaluate_cli.evaluate, cfg, capsys)
    assert code == 2 and len(lines) == 1, lines
    assert lines[0].startswith(f"error: {canonical_ckpt}: the checkpoint holds the canonical task"), lines
    assert "the data config is for the completion task (datamodules.completion.CompletionDataModule)" in lines[0]
    assert not (tmp_path / "data").exists()


def test_eval_with_data_of_the_checkpoints_task_goes_on(canonical_ckpt, compose_cfg, capsys):
    """Not red before: another data config of the same task (the thesis's cross-dataset tables) passes."""
    cfg = compose_cfg([f"ckpt_path={canonical_ckpt}", "data=canonical_synth", "data.image_size=48"],
                      config_name="eval")
    code, lines = run(evaluate_cli.evaluate, cfg, capsys)
    assert code == "reached", lines


def test_subprocess_train_with_a_canonical_checkpoint(canonical_ckpt, tmp_path):
    """The issue's command in a real process: ``lit3d-train TINY ckpt_path=<canonical ckpt>``."""
    env = {k: v for k, v in os.environ.items() if k != "HYDRA_FULL_ERROR"}
    env.update(WANDB_MODE="offline", WANDB_SILENT="true")
    res = subprocess.run([str(Path(sys.executable).parent / "lit3d-train"), *TINY, f"ckpt_path={canonical_ckpt}",
                          f"hydra.run.dir={tmp_path}/run", f"paths.data_dir={tmp_path}/data"],
                         cwd=REPO, env=env, capture_output=True, text=True, timeout=300)
    errors = [ln for ln in res.stderr.splitlines() if ln.startswith("error:")]
    assert res.returncode == 2 and len(errors) == 1 and res.stderr.strip().splitlines()[-1] == errors[0], res.stderr
    assert "holds the canonical task" in errors[0] and "Traceback" not in res.stderr
    assert not (tmp_path / "data").exists()
