"""One quality MLP trainer: the Lightning path trains the model ``fit_mlp`` trains; the metric
states and the batch order it relies on."""
from __future__ import annotations

import lightning.pytorch as pl
import numpy as np
import pytest
import scipy.stats
import torch
from tests.helpers.quality import make_dm

from datamodules.quality.batches import ShuffledBatches
from lit3d.features.matrix import minibatch_count, minibatches
from lit3d.quality.correlation import pearson, shape_corr_metrics, spearman
from lit3d.quality.evaluator import checkpoint_predictions
from lit3d.quality.module import QualityTask
from lit3d.quality.shape_metric import PerShapeCorrelation
from lit3d.quality.trainer import fit_mlp, init_mlp, init_mlp_many, predict


def _fit_lightning(dm, epochs: int, **task_kw) -> QualityTask:
    task = QualityTask(**task_kw)
    trainer = pl.Trainer(max_epochs=epochs, logger=False, enable_checkpointing=False, enable_progress_bar=False,
                         enable_model_summary=False, accelerator="cpu", devices=1)
    trainer.fit(task, datamodule=dm)
    return task


@pytest.mark.parametrize("net", [{"dropout": 0.2, "batch_norm": True}, {"dropout": 0.0, "batch_norm": False}])
def test_lightning_path_and_fit_mlp_give_the_same_model(tmp_path, net):
    dm = make_dm(tmp_path)  # 16 training rows: the last minibatch of one row joins the previous one
    task = _fit_lightning(dm, 6, net=net, lr=0.05, momentum=0.9, selection="all", seed=0)
    train, test = dm.split("train"), dm.split("test")
    cfg = task.train_config()
    assert (cfg.epochs, cfg.batch_size, cfg.seed) == (6, 3, 0)
    expected = predict(fit_mlp(train.columns(task.features), train.target, cfg), test.columns(task.features))
    got = checkpoint_predictions(task, test)["pred"]
    untrained = predict(init_mlp(len(task.features), cfg), test.columns(task.features))
    assert np.abs(expected - untrained).max() > 1e-3  # training moved the model: the comparison means something
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-5)


def test_init_mlp_is_fit_mlp_start():
    from lit3d.quality.trainer import TrainConfig

    cfg = TrainConfig(hidden=8, blocks=1, seed=3)
    single, batched = init_mlp(5, cfg), init_mlp_many(1, 5, cfg)
    x = torch.randn(4, 5)
    torch.testing.assert_close(single.eval()(x), batched.eval()(x[None])[0], rtol=1e-5, atol=1e-6)


def test_shuffled_batches_are_the_trainers_minibatches():
    n, bs = 16, 3
    sampler = ShuffledBatches(range(n), bs, seed=7)
    rng = np.random.default_rng(7)
    for _ in range(3):  # successive epochs continue one generator
        assert list(sampler) == [b.tolist() for b in minibatches(n, bs, rng)]
    assert len(sampler) == minibatch_count(n, bs) == 5
    assert len(ShuffledBatches(range(n), bs, drop_last=True)) == len(list(ShuffledBatches(range(n), bs, drop_last=True)))
    assert all(minibatch_count(k, 3) == len(minibatches(k, 3, rng)) for k in range(1, 20))


def test_per_shape_metric_equals_numpy_path():
    rng = np.random.default_rng(0)
    names = ["a", "b", "c"]
    ids = rng.integers(0, 3, 40)
    pred, target = rng.normal(size=40), rng.normal(size=40)
    target[ids == 2] = 0.5  # constant target on one shape -> 0.0, not NaN
    metric = PerShapeCorrelation(names)
    for chunk in np.array_split(np.arange(40), 4):  # several updates, as several batches
        metric.update(torch.tensor(pred[chunk]), torch.tensor(target[chunk]), torch.tensor(ids[chunk]))
    got = metric.compute()
    want = shape_corr_metrics("x", pred, target, np.array(names)[ids])
    assert got == pytest.approx({k[2:]: v for k, v in want.items()})
    assert got["pearson/c"] == 0.0 and got["spearman/c"] == 0.0
    a = ids != 2
    assert got["pearson/a"] == pytest.approx(scipy.stats.pearsonr(pred[ids == 0], target[ids == 0])[0])
    assert pearson(pred[a], target[a]) == pytest.approx(scipy.stats.pearsonr(pred[a], target[a])[0], abs=1e-12)
    assert spearman(pred[a], target[a]) == pytest.approx(scipy.stats.spearmanr(pred[a], target[a])[0], abs=1e-12)
