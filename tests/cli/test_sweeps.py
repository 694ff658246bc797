"""Collecting a multirun: one row per job, and mean ± sd per setting over seeds."""
from __future__ import annotations

import json
import logging
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml
from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra
from omegaconf import OmegaConf

from lit3d.runtime.compose import CONF_DIR
from lit3d.sweeps import CollectResults, collect, over_seeds
from tests.helpers.paths import REPO



def _job(root, name, overrides, metrics):
    d = root / name
    (d / ".hydra").mkdir(parents=True)
    (d / ".hydra" / "overrides.yaml").write_text(yaml.safe_dump(overrides))
    (d / ".hydra" / "hydra.yaml").write_text(yaml.safe_dump(
        {"hydra": {"sweeper": {"params": {"task.adversarial.use": "true,false", "seed": "0,1,2"}}}}))
    if metrics is not None:
        (d / "metrics.json").write_text(json.dumps(metrics))


def test_collect_groups_seeds_into_mean_and_sd(tmp_path):
    values = {("true", 0): 0.30, ("true", 1): 0.34, ("true", 2): 0.35, ("false", 0): 0.40, ("false", 1): 0.38}
    for n, ((adv, seed), v) in enumerate(values.items()):
        _job(tmp_path, str(n), ["experiment=completion_demo", f"task.adversarial.use={adv}", f"seed={seed}"],
             {"test/same/iou": v})
    _job(tmp_path, "5", ["experiment=completion_demo", "task.adversarial.use=false", "seed=2"], None)  # failed job
    text = collect(tmp_path, ["test/same/iou"], {"task.adversarial.use=true": 0.7})
    assert "no metrics.json" in text
    gan = np.array([0.30, 0.34, 0.35])
    assert f"| task.adversarial.use=true | 3 | {gan.mean():.3f} ± {gan.std(ddof=1):.3f} | 0.700 |" in text
    assert f"| task.adversarial.use=false | 2 | 0.390 ± {np.std([0.40, 0.38], ddof=1):.3f} | – |" in text
    assert (tmp_path / "sweep_results.md").read_text() == text


def test_every_metric_table_is_one_row_per_metric_not_one_row_of_hundreds(tmp_path):
    """A plain multirun (no metrics named) of a task with hundreds of test keys: the jobs table holds the
    monitored value, and the test metrics follow one row each, one column per job."""
    keys = [f"test/{split}/{m}/{c}" for split in ("same", "cross") for m in ("iou", "chamfer_l1", "fscore_1pct")
            for c in ("bench", "chair", "couch", "table")]
    for n, seed in enumerate((0, 1, 2)):
        _job(tmp_path, str(n), ["experiment=completion_demo", "task.adversarial.use=true", f"seed={seed}"],
             {"monitor": "val/iou", "monitored_value": 0.5 + 0.01 * n, **{k: 0.1 * n for k in keys}})
    _job(tmp_path, "3", ["experiment=completion_demo", "task.adversarial.use=true", "seed=3"], None)
    text = collect(tmp_path)
    widest = max(line.count("|") for line in text.splitlines())
    assert widest <= 6, widest  # metric + 3 jobs (or job, setting, monitored), not 24 metric columns
    assert "| job | setting | val/iou (monitored) |" in text and "| 1 | task.adversarial.use=true, seed=1 | 0.510 |" in text
    assert "| 3 | task.adversarial.use=true, seed=3 | no metrics.json |" in text
    assert "| test/same/iou/chair | 0.000 | 0.100 | 0.200 |" in text
    assert "| test/same/iou/chair | 0.100 ± 0.100 |" in text  # over seeds, one row per metric too


def test_no_seed_table_without_repeated_settings():
    assert over_seeds({"task.nets.k=50": {"m": 1.0}, "task.nets.k=100": {"m": 2.0}}, ["m"]) == {}


def test_seeds_given_on_the_command_line_are_grouped_too(tmp_path):
    """``-m ... +sweep=X seed=42,0,1``: seed is not a sweeper param of the sweep file but is swept."""
    (tmp_path / "multirun.yaml").write_text(yaml.safe_dump(
        {"hydra": {"overrides": {"task": ["experiment=completion_demo", "seed=42,0,1", "data.sizes={a: 1, b: 2}"]}}}))
    for n, (k, seed, v) in enumerate([(50, 42, 0.4), (50, 0, 0.5), (100, 42, 0.6), (100, 0, 0.8)]):
        d = tmp_path / str(n)
        (d / ".hydra").mkdir(parents=True)
        (d / ".hydra" / "overrides.yaml").write_text(yaml.safe_dump([f"task.nets.k={k}", f"seed={seed}"]))
        (d / ".hydra" / "hydra.yaml").write_text(yaml.safe_dump({"hydra": {"sweeper": {"params": {"task.nets.k": "50,100"}}}}))
        (d / "metrics.json").write_text(json.dumps({"m": v}))
    text = collect(tmp_path, ["m"])
    assert "| 0 | task.nets.k=50, seed=42 | 0.400 |" in text
    assert f"| task.nets.k=100 | 2 | 0.700 ± {np.std([0.6, 0.8], ddof=1):.3f} |" in text


def _hydra_callbacks(config_name: str, overrides: list[str]) -> dict:
    GlobalHydra.instance().clear()
    try:
        with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
            cfg = compose(config_name, overrides=overrides, return_hydra_config=True)
        return OmegaConf.to_container(cfg.hydra.callbacks, resolve=False)
    finally:
        GlobalHydra.instance().clear()


@pytest.mark.parametrize("config_name", ["train", "eval"])
def test_every_multirun_collects_by_default(config_name):
    assert _hydra_callbacks(config_name, [])["collect"] == {"_target_": "lit3d.sweeps.CollectResults", "metrics": None}
    # its columns can be set without "+"
    assert _hydra_callbacks(config_name, ["hydra.callbacks.collect.metrics=[test/a]"])["collect"]["metrics"] == ["test/a"]
    # a sweep config sets the table's metrics and title on the same callback
    collect_cb = _hydra_callbacks("train", ["experiment=completion_demo", "+sweep=completion_classifier"])["collect"]
    assert collect_cb["_target_"] == "lit3d.sweeps.CollectResults" and collect_cb["metrics"]
    assert "collect" not in _hydra_callbacks(config_name, ["~hydra.callbacks.collect"])


def test_plain_multirun_writes_sweep_results_and_single_run_does_not(tmp_path):
    """No callback on the command line: lit3d-summary (no training) as a 2-job multirun, then once."""
    env = {**os.environ, "OMP_NUM_THREADS": "1", "HYDRA_FULL_ERROR": "1"}
    exe = str(Path(sys.executable).parent / "lit3d-summary")
    sweep, run = tmp_path / "sweep", tmp_path / "run"
    res = subprocess.run([exe, "-m", "experiment=completion_demo", "seed=1,2", f"hydra.sweep.dir={sweep}"],
                         cwd=REPO, env=env, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr[-3000:]
    table = (sweep / "sweep_results.md").read_text()
    assert "| 0 | seed=1 |" in table and "| 1 | seed=2 |" in table
    res = subprocess.run([exe, "experiment=completion_demo", f"hydra.run.dir={run}"],
                         cwd=REPO, env=env, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr[-3000:]
    assert (run / ".hydra").is_dir() and not (run / "sweep_results.md").exists()


def test_a_collect_failure_does_not_fail_the_multirun(tmp_path, caplog):
    _job(tmp_path, "0", ["seed=0"], None)
    (tmp_path / "0" / "metrics.json").write_text("{not json")
    cfg = OmegaConf.create({"hydra": {"sweep": {"dir": str(tmp_path)}}})
    with caplog.at_level(logging.WARNING, logger="lit3d.sweeps"):
        CollectResults().on_multirun_end(cfg)
    assert "no sweep_results.md" in caplog.text and not (tmp_path / "sweep_results.md").exists()


@pytest.mark.parametrize("config_name", ["train", "eval"])
def test_every_multirun_keeps_the_job_dirs_of_an_earlier_one(config_name):
    assert _hydra_callbacks(config_name, [])["earlier_jobs"] == {"_target_": "lit3d.sweeps.KeepEarlierJobs"}


@pytest.mark.parametrize("command", [
    ["lit3d-summary", "-m", "experiment=completion_demo", "seed=1,2"],  # a plain multirun
    ["lit3d-train", "hparams_search=canonical_optuna", "experiment=canonical_tiny"],  # an in-memory Optuna study again
], ids=["plain", "optuna"])
def test_a_multirun_into_a_sweep_dir_with_earlier_jobs_is_refused(tmp_path, command):
    """``hydra.sweep.dir=X`` given to a second multirun: Hydra numbers its jobs from 0 again, so they ran in
    the first multirun's job dirs and replaced their results (config.yaml, metrics.json, checkpoints; an
    interrupted in-memory Optuna study run again too). Now one line and exit 2 before any job; the earlier
    job dirs are as they were."""
    sweep = tmp_path / "sweep"
    earlier = {}
    for i in (0, 1):
        (sweep / str(i) / ".hydra").mkdir(parents=True)
        (sweep / str(i) / "metrics.json").write_text(json.dumps({"test/x": i}))
        earlier[i] = (sweep / str(i) / "metrics.json").read_bytes()
    env = {k: v for k, v in os.environ.items() if k != "HYDRA_FULL_ERROR"}
    env["OMP_NUM_THREADS"] = "1"
    res = subprocess.run([str(Path(sys.executable).parent / command[0]), *command[1:], f"hydra.sweep.dir={sweep}",
                          f"paths.data_dir={tmp_path}/data"], check=False, cwd=REPO, env=env, capture_output=True, text=True,
                         timeout=300)
    lines = res.stderr.strip().splitlines()
    assert res.returncode == 2 and "Traceback" not in res.stderr, res.stderr[-3000:]
    assert lines[-1] == (f"error: {sweep}: holds the job dirs of an earlier multirun (0, 1); a new multirun numbers its "
                         "job dirs from 0 again and would replace them: leave hydra.sweep.dir to its default (a new "
                         "timestamped folder) or choose another one"), lines
    assert sorted(p.name for p in sweep.iterdir()) == ["0", "1"] and not (tmp_path / "data").exists()
    assert all((sweep / str(i) / "metrics.json").read_bytes() == earlier[i] for i in (0, 1))
