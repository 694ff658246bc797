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

from lit3d.runtime.compose import CONF_DIR
from tests.helpers.paths import REPO



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
    assert set(best["best_params"]) == {"task.optimizer.lr", "task.net.head.hidden"}
    lrs = {next(o for o in yaml.safe_load((sweep / str(i) / ".hydra" / "overrides.yaml").read_text())
                if o.startswith("task.optimizer.lr=")) for i in range(2)}
    assert len(lrs) == 2  # the sampler proposed two settings
    assert all((sweep / str(i) / "curves.png").is_file() for i in range(2))


def test_a_kept_study_opens_and_loads_again(tmp_path):
    """``hydra.sweeper.storage=sqlite:///...`` ended in optuna's AssertionError (its RDB storage's schema
    version stamped on a connection that SQLAlchemy 2 never commits) before any trial: the storage is now
    prepared first (lit3d.sweeps.prepare_study_storage), and the study keeps its trials across openings."""
    import optuna

    from lit3d.sweeps import prepare_study_storage

    url = f"sqlite:///{tmp_path / 'study.db'}"
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    for n in (1, 2):  # a new database, then one prepared before (left as it is)
        prepare_study_storage(url)
        study = optuna.create_study(study_name="s", storage=url, load_if_exists=True)
        study.optimize(lambda t: t.suggest_float("x", 0, 1), n_trials=1)
        assert len(optuna.load_study(study_name="s", storage=url).trials) == n


@pytest.mark.slow
def test_a_kept_study_resumes_after_a_kill_without_replacing_its_trial_dirs(tmp_path):
    """A 2-trial study kept in SQLite, killed (SIGKILL) during its second trial, then resumed: the resumed run
    adds its trial to the same study in a new sweep dir; the first run's trial dir is as it was. Resuming into
    the first run's sweep dir is refused with one line (its trial dirs would be numbered from 0 again)."""
    import time

    import optuna

    db = tmp_path / "study.db"
    env = {**os.environ, "OMP_NUM_THREADS": "1", "WANDB_MODE": "offline"}
    env.pop("HYDRA_FULL_ERROR", None)

    def command(sweep: Path, n: int) -> list[str]:
        return [str(Path(sys.executable).parent / "lit3d-train"), "hparams_search=canonical_optuna",
                "experiment=canonical_tiny", "debug=limit", "trainer.max_epochs=1", "test_after_fit=false",
                "logger=none", "callbacks.progress_bar=null", "evaluation.retrieval=null", f"hydra.sweeper.n_trials={n}",
                f"hydra.sweeper.storage=sqlite:///{db}", "hydra.sweeper.study_name=kept", f"hydra.sweep.dir={sweep}",
                f"paths.data_dir={tmp_path / 'data'}"]

    first, second = tmp_path / "sweep1", tmp_path / "sweep2"
    with open(tmp_path / "first.err", "w") as err:
        proc = subprocess.Popen(command(first, 2), cwd=REPO, env=env, stdout=subprocess.DEVNULL, stderr=err)
    try:
        t0 = time.monotonic()
        while not (first / "1" / ".hydra").is_dir():  # trial 0 finished, trial 1 started
            assert proc.poll() is None, (tmp_path / "first.err").read_text()[-3000:]
            assert time.monotonic() - t0 < 400, "timed out"
            time.sleep(0.05)
    finally:
        proc.kill()
        proc.wait(timeout=60)
    kept = (first / "0" / "metrics.json").read_bytes()
    res = subprocess.run(command(first, 1), cwd=REPO, env=env, capture_output=True, text=True, timeout=300)
    assert res.returncode == 2 and "Traceback" not in res.stderr, res.stderr[-3000:]
    assert res.stderr.strip().splitlines()[-1].startswith(f"error: {first}: holds the trial dirs of an earlier sweep "
                                                          "(0, 1); a resumed study")
    res = subprocess.run(command(second, 1), cwd=REPO, env=env, capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr[-3000:]
    assert (first / "0" / "metrics.json").read_bytes() == kept  # the first run's trial dir as it was
    trials = optuna.load_study(study_name="kept", storage=f"sqlite:///{db}").trials
    states = [t.state.name for t in trials]
    assert states == ["COMPLETE", "RUNNING", "COMPLETE"], states  # the killed trial stays RUNNING, never told
    assert json.loads((second / "0" / "metrics.json").read_text())["monitored_value"] == pytest.approx(trials[2].value)
    assert yaml.safe_load((second / "optimization_results.yaml").read_text())["best_value"] == pytest.approx(
        min(trials[0].value, trials[2].value))
