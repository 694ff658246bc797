"""The one trainer of the thesis MLP (SGD, MSE, batch 3): many candidate models at once for
Sequential Forward Search, one model for the final fit; ``training_corr`` binds Algorithm 4.1's
``corr(.)`` to training data.

The Lightning path (:class:`lit3d.quality.module.QualityTask`) trains the same model with the
same pieces: :func:`init_mlp` (initial weights from ``cfg.seed``), the batches of
:func:`lit3d.features.matrix.minibatches` drawn from ``np.random.default_rng(seed)`` (the
datamodule's ``ShuffledBatches``), :func:`make_optimizer`, mean squared error, and dropout masks
from ``torch.manual_seed(cfg.seed)`` at the start of training. For one seed and one training
split both give the same predictions up to float rounding (``tests/quality/test_quality_trainer.py``).
"""
from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from lit3d.features.matrix import FeatureMatrix, minibatches
from lit3d.quality.correlation import mean_per_shape_corr
from lit3d.quality.nets import BatchedQualityMLP, QualityMLP


# --------------------------------------------------------------------------- training
@dataclass
class TrainConfig:
    """The thesis's training set-up (ch. 4.2.6.1): SGD lr 1e-4, batch 3, 250 epochs, MSE.

    ``momentum`` / ``optimizer`` ("sgd" | "adam") are extensions (thesis: plain SGD).
    """

    hidden: int = 32
    blocks: int = 2
    dropout: float = 0.1
    batch_norm: bool = True
    optimizer: str = "sgd"
    lr: float = 1e-4
    momentum: float = 0.0
    weight_decay: float = 0.0
    batch_size: int = 3
    epochs: int = 250
    seed: int = 0

    def net_kwargs(self) -> dict:
        return {"hidden": self.hidden, "blocks": self.blocks, "dropout": self.dropout, "batch_norm": self.batch_norm}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any] | None) -> TrainConfig:
        d = dict(d or {})
        known = {f for f in cls.__dataclass_fields__}
        unknown = set(d) - known
        if unknown:
            raise KeyError(f"unknown training option(s) {sorted(unknown)} (known: {sorted(known)})")
        return cls(**d)


def make_optimizer(params, cfg: TrainConfig) -> torch.optim.Optimizer:
    if cfg.optimizer == "sgd":
        return torch.optim.SGD(params, lr=cfg.lr, momentum=cfg.momentum, weight_decay=cfg.weight_decay, foreach=True)
    if cfg.optimizer == "adam":
        return torch.optim.Adam(params, lr=cfg.lr, weight_decay=cfg.weight_decay, foreach=True)
    raise ValueError(f"unknown optimizer '{cfg.optimizer}' (sgd | adam)")


def init_mlp_many(n_models: int, in_features: int, cfg: TrainConfig) -> BatchedQualityMLP:
    """``n_models`` untrained thesis MLPs; model ``i``'s weights depend on ``cfg.seed`` and ``i`` only."""
    return BatchedQualityMLP(n_models, in_features, seed=cfg.seed, **cfg.net_kwargs())


def init_mlp(in_features: int, cfg: TrainConfig) -> QualityMLP:
    """The untrained :class:`QualityMLP` that :func:`fit_mlp` starts from (model 0 of :func:`init_mlp_many`)."""
    return init_mlp_many(1, in_features, cfg).to_single(0)


def fit_mlp_many(Xs: np.ndarray, y: np.ndarray, cfg: TrainConfig) -> BatchedQualityMLP:
    """Train ``M`` independent thesis MLPs at once.

    Xs: (M, N, d) float, y: (N,) float in [0, 1]. Same minibatch order for all models.
    Returns the batched model in eval mode. Deterministic for ``cfg.seed``.
    """
    # callable from inside Lightning's test loop (inference mode): train with autograd on
    with torch.inference_mode(False), torch.enable_grad():
        return _fit_mlp_many(Xs, y, cfg)


def _fit_mlp_many(Xs: np.ndarray, y: np.ndarray, cfg: TrainConfig) -> BatchedQualityMLP:
    Xs_t = torch.as_tensor(np.asarray(Xs), dtype=torch.float32)
    y_t = torch.as_tensor(np.asarray(y), dtype=torch.float32)
    m, n, d = Xs_t.shape
    net = init_mlp_many(m, d, cfg)
    opt = make_optimizer(net.parameters(), cfg)
    rng = np.random.default_rng(cfg.seed)
    torch_rng_state = torch.random.get_rng_state()
    torch.manual_seed(cfg.seed)  # dropout masks
    threads = torch.get_num_threads()
    # tiny matrices: one thread is faster, and far faster on a busy machine (no spin-waiting)
    torch.set_num_threads(1)
    try:
        net.train()
        for _ in range(cfg.epochs):
            for idx in minibatches(n, cfg.batch_size, rng):
                idx_t = torch.as_tensor(idx)
                pred = net(Xs_t[:, idx_t])
                # sum over models of each model's mean loss: the models do not interact
                loss = ((pred - y_t[idx_t]) ** 2).mean(1).sum()
                opt.zero_grad(set_to_none=True)
                loss.backward()
                opt.step()
    finally:
        torch.random.set_rng_state(torch_rng_state)
        torch.set_num_threads(threads)
    return net.eval()


def predict_many(net: BatchedQualityMLP, Xs: np.ndarray) -> np.ndarray:
    """(M, N, d) -> (M, N) float64 predictions in (0, 1)."""
    with torch.no_grad():
        return net.eval()(torch.as_tensor(np.asarray(Xs), dtype=torch.float32)).double().numpy()


def fit_mlp(X: np.ndarray, y: np.ndarray, cfg: TrainConfig) -> QualityMLP:
    """Train one thesis MLP on (N, d) features; returns a plain :class:`QualityMLP` (eval mode)."""
    return fit_mlp_many(np.asarray(X)[None], y, cfg).to_single(0).eval()


def predict(net: QualityMLP, X: np.ndarray) -> np.ndarray:
    with torch.no_grad():
        return net.eval()(torch.as_tensor(np.asarray(X), dtype=torch.float32)).double().numpy()


# --------------------------------------------------------------------------- SFS bound to training data
def training_corr(train: FeatureMatrix, cfg: TrainConfig, criterion: str = "train", kind: str = "pearson",
                  chunk: int = 64) -> Callable[[list[list[str]]], list[float]]:
    """Algorithm 4.1's ``corr(.)`` on the training folds only.

    criterion "train" (the thesis): train on ``train``, correlate the predictions on
    ``train`` with its targets. "inner_cv": leave-one-shape-out inside ``train``
    (out-of-fold predictions, still training data only). The correlation is the mean
    over training shapes of the per-shape ``kind`` correlation (as in the tables).
    """
    if criterion not in ("train", "inner_cv"):
        raise ValueError(f"unknown SFS criterion '{criterion}' (train | inner_cv)")

    def corr_many(sets: list[list[str]]) -> list[float]:
        out: list[float] = []
        for start in range(0, len(sets), chunk):
            group = sets[start:start + chunk]
            widths = {len(s) for s in group}
            if len(widths) != 1:
                raise ValueError("corr_many expects feature sets of one size per call")
            Xs = np.stack([train.columns(s) for s in group])
            if criterion == "train":
                preds = predict_many(fit_mlp_many(Xs, train.target, cfg), Xs)
            else:
                preds = np.zeros((len(group), len(train)))
                for shape in train.shape_names:
                    te = train.shapes == shape
                    net = fit_mlp_many(Xs[:, ~te], train.target[~te], cfg)
                    preds[:, te] = predict_many(net, Xs[:, te])
            out += [mean_per_shape_corr(p, train.target, train.shapes, kind) for p in preds]
        return out

    return corr_many


