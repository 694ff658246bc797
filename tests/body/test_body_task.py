"""The body regressor as a task: its replay stream, DataModule, LightningModule, checkpoint as the body
fit's start, evaluator tables, and ``lit3d-train experiment=body_demo`` -> Ctrl-C -> ``ckpt_path=last``
-> ``lit3d-eval`` as a user runs them."""
from __future__ import annotations

import json
import signal
import subprocess
import time

import numpy as np
import pytest
import torch

pytest.importorskip("anny", reason="the body task needs lit3d[body] (anny, roma)")

from datamodules.body import BodyDataModule
from datamodules.body.replay import ReplayBuffer, ReplayStream
from lit3d.body.evaluator import flat_metrics, write_results
from lit3d.body.module import BodyRegressorTask
from lit3d.body_fit.regressor import load_regressor
from tests.helpers.runs import BIN, REPO, child_env, load_checkpoint, start_script

SMALL = {"preprocess": {"size": 32}, "batch_size": 16, "draw": 8, "reuse": 8.0, "buffer": 64, "val_people": 16,
         "test_people": 0}


def _people(n: int, first: int = 0) -> dict[str, torch.Tensor]:
    ids = torch.arange(first, first + n, dtype=torch.float32)
    return {"image": ids[:, None, None, None].expand(n, 2, 4, 4).clone(), "phenotype": ids[:, None].repeat(1, 6)}


def test_replay_buffer_keeps_the_newest_people_and_samples_only_stored_ones():
    buf = ReplayBuffer(5)
    buf.add(_people(4))
    buf.add(_people(3, first=4))  # 7 people into a ring of 5: people 0 and 1 are overwritten
    assert buf.n == 5 and buf.data["image"].dtype == torch.float16
    gen = torch.Generator().manual_seed(0)
    got = [buf.sample(200, gen) for _ in range(40)]
    assert all(len(g["image"]) == 5 for g in got)  # at most the people stored
    assert {v for g in got for v in g["phenotype"][:, 0].tolist()} == {2.0, 3.0, 4.0, 5.0, 6.0}
    assert got[0]["image"].dtype == torch.float32


def test_replay_stream_uses_each_person_about_reuse_times_and_resumes_after_the_drawn_people():
    calls = []

    def draw(first, n):
        calls.append(first)
        return _people(n, first)

    stream = ReplayStream(draw, batch_size=4, per_draw=8, reuse=2.0, buffer=100, seed=0)
    batches = [b for _, b in zip(range(12), iter(stream))]
    assert len(batches) == 12 and calls == [0, 8, 16]  # 8 people * 2 uses / 4 a batch = 4 batches a draw
    assert stream.drawn == 24
    resumed = ReplayStream(draw, 4, 8, 2.0, 100, 0, drawn=stream.drawn)
    next(iter(resumed))
    assert calls[-1] == 24  # the next people, not the first again


def test_the_datamodule_refuses_the_held_out_draws():
    for seed in (999, 1000, 1999, 2000):
        with pytest.raises(ValueError, match="held out"):
            BodyDataModule(seed=seed)
    with pytest.raises(ValueError, match="test_seed"):
        BodyDataModule(seed=7, test_seed=8)


def test_a_few_steps_lower_the_validation_loss_and_the_checkpoint_starts_the_fit(tmp_path):
    """Trained 40 steps on rendered people, the regressor's validation loss falls well below the
    untrained one's; its Lightning checkpoint loads as the body fit's start and predicts as the module."""
    import lightning.pytorch as pl

    torch.manual_seed(0)
    dm = BodyDataModule(**SMALL, seed=7)
    task = BodyRegressorTask(preprocess={"size": 32}, net={"width": 8, "hidden": 64}, lr=3e-3)
    trainer = pl.Trainer(max_steps=40, limit_train_batches=20, max_epochs=-1, logger=False, enable_progress_bar=False,
                         enable_model_summary=False, default_root_dir=tmp_path, num_sanity_val_steps=0,
                         enable_checkpointing=False)
    before = trainer.validate(task, datamodule=dm, verbose=False)[0]["val/loss"]
    trainer.fit(task, datamodule=dm)
    after = trainer.validate(task, datamodule=dm, verbose=False)[0]["val/loss"]
    assert after < 0.6 * before, (before, after)
    assert dm.state_dict()["drawn"] >= 40 * 16 / 8  # people drawn: steps * batch / reuse

    path = tmp_path / "body.ckpt"
    trainer.save_checkpoint(path)
    ck = torch.load(path, weights_only=True)
    ck["lit3d"] = {"task": {"name": "body"}}  # as the metadata callback of lit3d-train writes it
    torch.save(ck, path)
    reg = load_regressor(path)
    batch = dm.datasets["val"].people
    task.eval()
    with torch.no_grad():
        want = task(batch["image"][:3], batch["extras"][:3])
        got = reg.net.decode(reg.net(batch["image"][:3], batch["extras"][:3]))
    for k in want:
        torch.testing.assert_close(got[k], want[k])
    assert reg.prep.size == 32


def test_results_table_reads_the_flattened_spreads(tmp_path):
    spread = {"median": 14.0, "q25": 12.0, "q75": 16.0, "mean": 14.2, "min": 9.0, "max": 30.0, "n": 20}
    summary = {"anny": {"refined": {"canonical_mm": spread, "posed_mm": {**spread, "median": 21.0},
                                    "phenotype_abs": {"height": spread}, "cpu_s": {**spread, "median": 1.5}},
                        "cpu_s": {**spread, "median": 1.5}},
               "faust": {"refined": {"chamfer": spread, "f@0.017": {**spread, "median": .5, "q25": .4, "q75": .6},
                                     "f@0.034": {**spread, "median": .89, "q25": .83, "q75": .92}, "poor_fit": 5},
                         "poor_fit": 5}}
    m = flat_metrics(summary)
    assert m["test/faust/refined/f@2%"] == .89 and m["test/faust/refined/f@2%_q25"] == .83
    assert m["test/anny/refined/posed_mm"] == 21.0 and m["test/anny/cpu_s"] == 1.5
    assert m["test/faust/refined/poor_fit"] == 5.0
    text = write_results(m, tmp_path).read_text()
    assert "| regressor + refinement | 14 [12-16] | 21 [12-16] | 1.50 [12.00-16.00] |" in text
    assert "| regressor + refinement | 14 [12-16] | 0.50 [0.40-0.60] | 0.89 [0.83-0.92] |" in text


DEMO = ["experiment=body_demo", "logger=none", "callbacks.progress_bar=null", "data.val_people=8", "data.test_people=8",
        "evaluation.anny_people=1", "callbacks.resume_state.every_n_train_batches=1"]


def test_train_ctrl_c_resume_and_evaluate_the_checkpoint(tmp_path):
    """``lit3d-train experiment=body_demo``: Ctrl-C keeps ``last.ckpt`` with the people drawn so far,
    ``ckpt_path=last`` resumes to the end, and ``lit3d-eval`` of the best checkpoint writes the fit's
    tables, its measures and a picture."""
    run = tmp_path / "run"
    last = run / "checkpoints" / "last.ckpt"
    proc = start_script(["lit3d-train", *DEMO, f"hydra.run.dir={run}", "trainer.max_steps=100000",
                         "test_after_fit=false"], tmp_path / "first")
    t0 = time.monotonic()
    while not (last.is_file() and load_checkpoint(last)["global_step"] >= 3):
        assert proc.poll() is None, (tmp_path / "first.err").read_text()[-3000:]
        assert time.monotonic() - t0 < 240, "no checkpoint after 240 s"
        time.sleep(0.2)
    proc.send_signal(signal.SIGINT)
    assert proc.wait(timeout=120) == 143
    saved = load_checkpoint(last)
    assert saved["BodyDataModule"]["drawn"] >= 8  # the stream's state: a resume draws the next people
    res = subprocess.run([str(BIN / "lit3d-train"), *DEMO, f"hydra.run.dir={run}",
                          f"trainer.max_steps={saved['global_step'] + 20}", "test_after_fit=false", "ckpt_path=last"],
                         cwd=REPO, env=child_env(), capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr[-3000:]
    assert load_checkpoint(last)["global_step"] == saved["global_step"] + 20
    best = sorted((run / "checkpoints").glob("best-*.ckpt"))[-1]
    res = subprocess.run([str(BIN / "lit3d-eval"), f"ckpt_path={best}", "n_figures=1", f"hydra.run.dir={tmp_path / 'eval'}"],
                         cwd=REPO, env=child_env(), capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr[-3000:]
    metrics = json.loads((tmp_path / "eval" / "metrics.json").read_text())
    assert np.isfinite(metrics["test/loss"]) and 0 < metrics["test/anny/refined/posed_mm"] < 500
    assert "regressor + refinement" in (tmp_path / "eval" / "results.md").read_text()
    assert (tmp_path / "eval" / "body_fits.png").stat().st_size > 10_000


@pytest.mark.parametrize("override, line", [
    ("data.reuse=0", "data.reuse=0: expected a number > 0"),
    ("data.draw=0", "data.draw=0: expected a whole number of items >= 1"),
    ("task.preprocess.size=4", "task.preprocess.size=4: expected an integer >= 8"),
])
def test_bad_body_settings_are_one_line_each(compose_cfg, override, line):
    from lit3d.runtime.config_checks import config_problems

    problems = config_problems(compose_cfg(["experiment=body_regressor", override]))
    assert problems == [line]


def test_the_recipe_and_the_data_agree_on_the_crop(compose_cfg):
    """The crop is the task's: the data reads it from ``task.preprocess`` (one source of sizes)."""
    from omegaconf import OmegaConf

    cfg = compose_cfg(["experiment=body_regressor", "task.preprocess.size=32"])
    assert OmegaConf.to_container(cfg.data.preprocess, resolve=True) == OmegaConf.to_container(cfg.task.preprocess)
    assert cfg.data.preprocess.size == 32
