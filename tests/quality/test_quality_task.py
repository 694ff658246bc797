"""Quality DataModule + LightningModule + checkpoint -> predict_from_features, and the synthetic claim.

The wiring tests use a cheap geometric stand-in for the renderer's feature table
(``tests.helpers.quality.fake_features``, named like the real features) so they run in seconds; the
synthetic-claim test uses the real renderer and is marked slow.
"""
from __future__ import annotations

import math

import lightning.pytorch as pl
import pytest
import torch

from datamodules.quality import SEVERITY_NAME, QualityDataModule
from lit3d.quality.predict import QualityCheckpointError, load_predictor, predict_from_features
from lit3d.quality.protocol import LearnedScore, TrainConfig, baseline_methods, leave_one_shape_out
from lit3d.quality.module import QualityTask
from tests.helpers.quality import make_dm


def test_datamodule_prepares_once_and_describes(tmp_path):
    dm = make_dm(tmp_path)
    dm.prepare_data()
    mtime = (dm.cache_dir / "matrix.npz").stat().st_mtime_ns
    dm.prepare_data()  # cached: nothing recomputed
    assert (dm.cache_dir / "matrix.npz").stat().st_mtime_ns == mtime
    dm.setup("fit")
    info = dm.describe()
    assert info["pairs"] == 4 * 4 * 2 and info["target"] == SEVERITY_NAME
    assert "NOT a human opinion score" in info["target_note"]
    assert info["splits"]["test"]["shapes"] == ["rock"] and info["splits"]["val"]["shapes"] == ["torus"]
    assert sorted(set(dm.matrix.target)) == [0.5, 1.0]
    batch = next(iter(dm.train_dataloader()))
    assert batch["x"].shape == (3, len(dm.feature_names)) and batch["x"].dtype == torch.float32
    png = dm.show(2, tmp_path / "show.png")
    assert png.stat().st_size > 0


def test_task_trains_checkpoints_and_predicts(tmp_path):
    dm = make_dm(tmp_path)
    task = QualityTask(lr=0.01, momentum=0.9, sfs={"max_features": 3, "epochs": 10})
    settings = {"baselines": None, "cv": True, "cv_epochs": 10, "cv_methods": ["ours_sfs"], "cross_data": None}
    trainer = pl.Trainer(max_epochs=8, logger=False, enable_checkpointing=False, enable_progress_bar=False,
                         enable_model_summary=False, default_root_dir=str(tmp_path))
    trainer.fit(task, datamodule=dm)
    assert 1 <= len(task.features) <= 3 and task.sfs_info["selected"] == task.features
    trainer.test(task, datamodule=dm)
    m = {k: float(v) for k, v in trainer.callback_metrics.items()}
    from lit3d.quality import evaluator

    evaluation = evaluator.protocol(task, dm, settings)  # baselines + leave-one-shape-out (as run_evaluation does)
    m.update(evaluation.metrics)
    for key in ("test/ours/pearson", "test/ours/spearman/rock", "test/chamfer/pearson", "test/single_best/spearman",
                "test/cv/ours_sfs/pearson/blob", "test/cv/chamfer/spearman"):
        assert key in m and math.isfinite(m[key]), key
    ckpt = tmp_path / "q.ckpt"
    trainer.save_checkpoint(ckpt)
    raw = torch.load(ckpt, map_location="cpu", weights_only=True)  # plain values only
    assert raw["quality"]["features"] == task.features and raw["quality"]["scaling"]["name"] == SEVERITY_NAME
    # the checkpoint alone reproduces the model's prediction for one pair's feature table
    test = dm.split("test")
    table = dict(zip(test.names, test.X[0]))
    expected = float(task.eval()(torch.tensor(test.columns(task.features)[:1], dtype=torch.float32))[0])
    assert predict_from_features(ckpt, table) == pytest.approx(expected, abs=1e-6)
    assert load_predictor(ckpt).features == task.features
    assert load_predictor(ckpt).feature_options == {}  # fake features: no render options
    with pytest.raises(QualityCheckpointError, match="lacks"):
        predict_from_features(ckpt, {"chamfer": 0.1})
    restored = QualityTask.load_from_checkpoint(ckpt, map_location="cpu")
    assert restored.features == task.features
    # report + scatter plots
    md = evaluator.write_results(m, tmp_path).read_text()
    assert "Leave-one-shape-out" in md and "ordinal severity" in md and "| rock |" in md
    figures = evaluator.write_figures(task, dm, tmp_path, evaluation=evaluation)
    assert len(figures) == 2 and all(p.stat().st_size > 0 for p in figures)


def test_report_puts_thesis_table_beside_ours(tmp_path):
    from lit3d.quality.report import write_results

    m = {}
    for s in ("armadillo", "dyno", "rockerarm", "venus"):
        for meth in ("chamfer", "ours_sfs"):
            m[f"test/cv/{meth}/pearson/{s}"] = 0.5
    m.update({"test/cv/chamfer/pearson": 0.5, "test/cv/ours_sfs/pearson": 0.5})
    md = write_results(m, tmp_path).read_text()
    assert "thesis table 4.2" in md and "| average (thesis) | 0.12 |" in md


@pytest.mark.slow
def test_synthetic_learned_score_beats_every_baseline(tmp_path):
    """Real renderer features, 4 shapes x 6 distortions x 4 levels, fixed seed: leave-one-shape-out
    Spearman of the learned score with the ordinal severity above every single baseline measure.

    Every image measure at 48 px on 2 styles; SFS scored by leave-one-shape-out inside the training
    shapes (``criterion="inner_cv"``, Spearman), still never on the held-out shape. Measured (seed 0):
    ours .814 vs single best .804, MS-SSIM .773, PSNR .759, MSE .755, Chamfer .615; with the thesis's
    criterion (fit and score on the training set) ours was .763: the margin is small at this scale.
    """
    dm = QualityDataModule(data_dir=str(tmp_path / "q"), synth={"shapes": ["blob", "bumpy", "torus", "rock"], "n_levels": 4},
                           feature_tables={"options": dict(size=48, styles=["ceramic_lightbulb", "metal_lead"], n_samples=2000)},
                           seed=0)
    dm.setup()
    fm = dm.matrix
    methods = {"ours": lambda: LearnedScore(TrainConfig(lr=0.01, momentum=0.9, epochs=60), "sfs", criterion="inner_cv",
                                            sfs_kind="spearman", max_features=6,
                                            sfs_cfg=TrainConfig(lr=0.01, momentum=0.9, epochs=30))}
    methods.update({k: (lambda k=k: baseline_methods(fm.names)[k]) for k in baseline_methods(fm.names)})
    res = leave_one_shape_out(fm, methods)
    ours = res.pop("ours").mean_spearman
    assert set(res) == {"chamfer", "hausdorff", "mse", "psnr", "ms_ssim", "single_best"}
    for name, r in res.items():
        assert ours > r.mean_spearman, (name, ours, r.mean_spearman)


@pytest.mark.parametrize("experiment", ["quality_demo", "quality_paper"])
def test_experiment_configs_compose(compose_cfg, experiment):
    from lit3d.runtime.build import task_kwargs

    cfg = compose_cfg([f"experiment={experiment}"])
    assert cfg.task_info.name == "quality" and cfg.data._target_ == "datamodules.quality.QualityDataModule"
    kw = task_kwargs(cfg.task)
    QualityTask(**kw)  # plain kwargs build the task
    assert cfg.data.batch_size == 3
    assert cfg.evaluation.cv is True and "cv" not in kw  # the protocol's settings: the evaluator's, not the task's


@pytest.mark.parametrize("data", ["liris_epfl", "liris_masking", "guo2016"])
def test_real_data_configs_compose(compose_cfg, data):
    cfg = compose_cfg(["experiment=quality_paper", f"data={data}", "data.root=/nowhere"])
    assert cfg.data.source == data
