"""Types and ranges of config values are checked in one place before any work,
and ``lit3d-summary`` answers a bad net size with the one line ``lit3d-train`` gives (fault 16)."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from lit3d.cli.common import cli_main, run_cli
from lit3d.runtime.compose import compose_config
from lit3d.runtime.config_checks import RULES, Rule, config_problems, expected, problem
from tests.helpers.paths import REPO

EXPERIMENTS = sorted(p.stem for p in (REPO / "conf" / "experiment").glob("*.yaml"))

# (override, the one line it gives)
BAD_VALUES = [
    ("task.optimizer.lr_g=abc", "error: task.optimizer.lr_g=abc: expected a number > 0"),
    ("task.optimizer.lr_g=-1", "error: task.optimizer.lr_g=-1: expected a number > 0"),
    ("trainer.max_epochs=1.5", "error: trainer.max_epochs=1.5: expected an integer >= 0, or -1 (no limit), or null"),
    ("trainer.max_epochs=-5", "error: trainer.max_epochs=-5: expected an integer >= 0, or -1 (no limit), or null"),
    ("data.batch_size=-1", "error: data.batch_size=-1: expected an integer >= 1"),
    ("data.batch_size=0", "error: data.batch_size=0: expected an integer >= 1"),
    ("seed=abc", "error: seed=abc: expected an integer >= 0 (and 1 more)"),  # data.seed is ${seed}
    ("data.num_workers=-1", "error: data.num_workers=-1: expected an integer >= 0"),
    ("task.nets.latent_dim=0", "error: task.nets.latent_dim=0: expected an integer >= 1"),
    ("task.adversarial.use=yes", "error: task.adversarial.use=yes: expected true or false"),
    ("trainer.fast_dev_run=-2", "error: trainer.fast_dev_run=-2: expected true or false, or an integer >= 0"),
]


def _never_run():
    raise AssertionError("the command went on to run: the bad value was not caught before any work")


def _one_line(capsys) -> list[str]:
    return [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]


@pytest.mark.parametrize("override,line", BAD_VALUES, ids=[b[0] for b in BAD_VALUES])
def test_bad_value_is_one_line_before_any_work(override, line, tmp_path, capsys, monkeypatch):
    """What ``lit3d-train``/``lit3d-data``/``lit3d-summary`` run (:func:`cli_main`): exit 2, one line
    naming the key, the value and what is expected, and nothing made (the run dir not even claimed)."""
    monkeypatch.delenv("HYDRA_FULL_ERROR", raising=False)
    run_dir = tmp_path / "run"
    with pytest.raises(SystemExit) as info:
        cli_main(_never_run, ["experiment=completion_demo", override, f"hydra.run.dir={run_dir}"])
    assert info.value.code == 2 and _one_line(capsys) == [line]
    assert not run_dir.exists()


def test_eval_config_is_checked_too(tmp_path, capsys, monkeypatch):
    monkeypatch.delenv("HYDRA_FULL_ERROR", raising=False)
    with pytest.raises(SystemExit) as info:
        cli_main(_never_run, ["ckpt_path=x.ckpt", "n_figures=-1", f"hydra.run.dir={tmp_path}/run"], config_name="eval")
    assert info.value.code == 2 and _one_line(capsys) == ["error: n_figures=-1: expected an integer >= 0"]


def test_multirun_jobs_check_their_values_in_run_cli(compose_cfg, capsys, monkeypatch):
    """A job of a multirun is composed by Hydra, not by cli_main: :func:`run_cli` checks it."""
    monkeypatch.delenv("HYDRA_FULL_ERROR", raising=False)
    cfg = compose_cfg(["experiment=completion_demo", "data.batch_size=0"])
    with pytest.raises(SystemExit) as info:
        run_cli(lambda c: _never_run(), cfg)
    assert info.value.code == 2 and _one_line(capsys) == ["error: data.batch_size=0: expected an integer >= 1"]


@pytest.mark.parametrize("experiment", EXPERIMENTS)
def test_every_shipped_experiment_passes(experiment):
    assert config_problems(compose_config("train", [f"experiment={experiment}"], return_hydra_config=True)) == []


@pytest.mark.parametrize("task", ["completion", "canonical", "quality"])
def test_eval_with_a_task_and_no_data_passes(task):
    """``lit3d-eval task=NAME ckpt_path=...`` (make demo's call): the task's sizes interpolate the absent data
    node to null until the checkpoint's config arrives; that is not a bad value."""
    cfg = compose_config("eval", ["ckpt_path=x.ckpt", f"task={task}"], return_hydra_config=True)
    assert config_problems(cfg) == []
    assert config_problems(compose_config("train", ["experiment=completion_demo", "data.target_res=null"],
                                          return_hydra_config=True))  # with data, a null size still counts


def test_rules_read_as_a_table():
    """The range grammar, both ends, ``or`` and ``null``; every rule's range parses."""
    rule = Rule("x", "int?", ">= 0 or == -1", "(no limit)")
    assert [problem(rule, v) is None for v in (0, 5, -1, None, -2, 1.5, "3", True)] == [
        True, True, True, True, False, False, False, False]
    unit = Rule("x", "number", "[0, 1)")
    assert [problem(unit, v) is None for v in (0, 0.5, 1, -0.1, float("nan"))] == [True, True, False, False, False]
    assert expected(Rule("x", "bool|int", ">= 0")) == "true or false, or an integer >= 0"
    for r in RULES:  # a typo in a range would only show when a user hits that key
        problem(r, 1)


def test_max_epochs_minus_one_is_lightnings_no_limit():
    cfg = compose_config("train", ["experiment=completion_demo", "trainer.max_epochs=-1"], return_hydra_config=True)
    assert config_problems(cfg) == []


def test_subprocess_max_epochs_negative_is_one_line_not_hydras_block(tmp_path):
    """The installed ``lit3d-train`` (the real process): exit 2 and the one line, not Hydra's 4-line block."""
    env = {k: v for k, v in os.environ.items() if k != "HYDRA_FULL_ERROR"}
    res = subprocess.run([str(Path(sys.executable).parent / "lit3d-train"), "experiment=completion_demo",
                          "trainer.max_epochs=-5", f"hydra.run.dir={tmp_path}/run", f"paths.data_dir={tmp_path}/data"],
                         cwd=REPO, env=env, capture_output=True, text=True, timeout=120)
    assert res.returncode == 2, res.stderr
    assert res.stderr.strip().splitlines() == [
        "error: trainer.max_epochs=-5: expected an integer >= 0, or -1 (no limit), or null"]
    assert not (tmp_path / "run").exists() and not (tmp_path / "data").exists()


# ------------------------------------------------------------------ fault 16: lit3d-summary
def _summary_line(compose_cfg, capsys, overrides: list[str]) -> str:
    from lit3d.cli.summary import summary

    with pytest.raises(SystemExit) as info:
        run_cli(summary, compose_cfg(overrides))
    lines = _one_line(capsys)
    assert info.value.code == 2 and len(lines) == 1, lines
    return lines[0]


def _train_line(compose_cfg, capsys, overrides: list[str], tmp_path) -> str:
    from lit3d.cli.train import train

    with pytest.raises(SystemExit) as info:
        run_cli(train, compose_cfg([*overrides, "logger=none"]))
    lines = _one_line(capsys)
    assert info.value.code == 2 and len(lines) == 1, lines
    assert not (tmp_path / "data").exists()  # refused before the data was touched
    return lines[0]


@pytest.mark.parametrize("overrides", [
    ["experiment=completion_demo", "task.nets.out_res=63"],
    ["experiment=completion_demo", "task.nets.latent_dim=0"],
    ["experiment=canonical_tiny", "task.net.image_size=7"],
], ids=["out_res=63", "latent_dim=0", "image_size=7"])
def test_summary_gives_the_line_train_gives(overrides, compose_cfg, capsys, monkeypatch, tmp_path):
    monkeypatch.delenv("HYDRA_FULL_ERROR", raising=False)
    line = _summary_line(compose_cfg, capsys, overrides)
    assert line.startswith(("error: task config: out_res=63 but", "error: task.nets.latent_dim=0: expected",
                            "error: task.net.image_size=7: expected")), line
    assert line == _train_line(compose_cfg, capsys, overrides, tmp_path)


def test_summary_of_nets_that_cannot_run_at_their_size(compose_cfg, capsys, monkeypatch):
    """Six pooling levels on a 48^2 image: the meta forward's shape error as one line."""
    monkeypatch.delenv("HYDRA_FULL_ERROR", raising=False)
    line = _summary_line(compose_cfg, capsys, ["experiment=canonical_tiny", "task.net.lfe.channels=[4,4,4,4,4,4]"])
    assert line.startswith("error: task config: the nets do not run at these sizes (") and "too small" in line, line
