"""Rendering-based shape quality (thesis ch. 4) as a LightningModule: the thesis MLP on the
selected rendering features, its optimiser, loss, metrics and logging. Nothing else.

Batches come from ``datamodules.quality``:
    x        (B, F) float32  every feature of the pair (the datamodule's ``feature_names``)
    y        (B,)   float32  target in [0, 1], higher = more distorted (MOS or ordinal severity)
    shape_id (B,)   int64    index into the datamodule's ``shape_names``
    shape list[str], item list[str]

Before fitting, :class:`lit3d.quality.feature_selection.FeatureSelection` (returned by
:meth:`QualityTask.configure_callbacks`) chooses the input features on the training split
(Sequential Forward Search, Algorithm 4.1, or all) and calls :meth:`QualityTask.use_features`.
Training is the one trainer's recipe (:mod:`lit3d.quality.trainer`): :func:`init_mlp` weights,
the datamodule's ``ShuffledBatches`` (= :func:`lit3d.features.matrix.minibatches`),
:func:`make_optimizer`, MSE, dropout masks from ``torch.manual_seed(seed)`` at train start; thesis:
SGD lr 1e-4, batch 3, 250 epochs. The checkpoint stores the selected feature names and the
target scaling (``checkpoint["quality"]``, plain values) so ``lit3d.quality.predict`` and
``lit3d-score --ckpt`` can use it without the data.

Logged: ``val/mse``, ``val/pearson``, ``val/spearman`` (mean over validation shapes);
``test/ours/<kind>[/<shape>]`` and ``test/n_features``. Correlations come from
:class:`~lit3d.quality.shape_metric.PerShapeCorrelation`, whose states are gathered over DDP
ranks before computing. ``baselines``, ``cv``, ``cv_epochs``, ``cv_methods`` and ``cross_data``
are evaluation settings (the config's ``evaluation`` node) of :func:`lit3d.quality.evaluator.protocol`
(``test/<baseline>/...``, ``test/cv/...``, ``test/cross/...``), not this module's.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import lightning.pytorch as pl
import torch
import torch.nn.functional as F

from lit3d.features.matrix import TargetScaling
from lit3d.quality.feature_selection import FeatureSelection
from lit3d.quality.nets import QualityMLP, count_parameters
from lit3d.quality.shape_metric import PerShapeCorrelation
from lit3d.quality.task_methods import filter_features  # noqa: F401  (re-exported)
from lit3d.quality.trainer import TrainConfig, init_mlp, make_optimizer
from lit3d.utils.evaluation import legacy_settings

CKPT_KEY = "quality"
# the MLP of a checkpoint saved without a net node: the thesis's (TrainConfig's defaults, written once there)
NET_DEFAULTS = TrainConfig().net_kwargs()
# the evaluation settings (the config's ``evaluation`` node, :mod:`lit3d.quality.evaluator`) that checkpoints
# written before that node hold among the task's hyper-parameters, with the constructor's defaults then
EVALUATION_LEGACY = {"baselines": None, "cv": False, "cv_epochs": None, "cv_methods": ("ours_all", "ours_sfs"),
                     "cross_data": None}


class QualityTask(pl.LightningModule):
    """Thesis MLP on (selected) rendering features, predicting distortion in [0, 1]."""

    evaluation_legacy = EVALUATION_LEGACY  # read by lit3d-eval for checkpoints saved before the evaluation node

    def __init__(
        self,
        net: Mapping[str, Any] | None = None,
        optimizer: str = "sgd",
        lr: float = 1e-4,
        momentum: float = 0.0,
        weight_decay: float = 0.0,
        selection: str = "sfs",
        sfs: Mapping[str, Any] | None = None,
        include: Sequence[str] | None = None,
        exclude: Sequence[str] | None = None,
        features: Sequence[str] | None = None,
        seed: int = 0,
        **legacy_evaluation,
    ):
        """``legacy_evaluation``: the evaluation settings (:data:`EVALUATION_LEGACY`) that checkpoints written
        before they got their own config node hold among these hyper-parameters; accepted and ignored
        (``lit3d-eval`` reads them from the checkpoint), any other keyword is a ValueError."""
        super().__init__()
        legacy_settings(type(self).__name__, legacy_evaluation, EVALUATION_LEGACY)
        self.save_hyperparameters(ignore=list(legacy_evaluation))
        self.net_kwargs = {**NET_DEFAULTS, **dict(net or {})}
        self.features: list[str] = []
        self.sfs_info: dict | None = None
        self.net: QualityMLP | None = None
        self.feature_index: torch.Tensor | None = None
        self.scaling: TargetScaling | None = None
        self.dataset_name: str | None = None
        self.feature_options: dict | None = None
        self.val_corr = PerShapeCorrelation()
        self.test_corr = PerShapeCorrelation()
        if features:
            self.use_features(features)

    # ------------------------------------------------------------ wiring
    def train_config(self, epochs: int | None = None) -> TrainConfig:
        """This task's training set-up as the one trainer's :class:`TrainConfig` (epochs default:
        ``trainer.max_epochs`` or 250; batch size: the datamodule's or 3)."""
        hp = self.hparams
        if epochs is None:
            epochs = int(self.trainer.max_epochs) if self._trainer is not None and self.trainer.max_epochs else 250
        dm = getattr(self._trainer, "datamodule", None) if self._trainer is not None else None
        return TrainConfig(**{k: self.net_kwargs[k] for k in NET_DEFAULTS}, optimizer=hp.optimizer, lr=hp.lr,
                           momentum=hp.momentum, weight_decay=hp.weight_decay,
                           batch_size=int(getattr(dm, "batch_size", 3) or 3), epochs=int(epochs), seed=int(hp.seed))

    def use_features(self, features: Sequence[str], sfs_info: dict | None = None) -> None:
        """Build the untrained MLP for ``features`` (the one trainer's :func:`init_mlp`)."""
        self.features, self.sfs_info = list(features), sfs_info
        self.net = init_mlp(len(self.features), TrainConfig(**self.net_kwargs, seed=int(self.hparams.seed)))

    def bind_data(self, data_feature_names: Sequence[str], shape_names: Sequence[str]) -> None:
        """Columns of the data's ``x`` this model reads, and the names behind ``shape_id``."""
        pos = {n: i for i, n in enumerate(data_feature_names)}
        missing = [f for f in self.features if f not in pos]
        if missing:
            raise KeyError(f"the data lacks {len(missing)} feature(s) this model uses, e.g. {missing[:3]}")
        self.feature_index = torch.tensor([pos[f] for f in self.features], dtype=torch.long)
        self.val_corr.shape_names = self.test_corr.shape_names = list(shape_names)

    def configure_callbacks(self) -> list[pl.Callback]:
        return [FeatureSelection()]

    def configure_optimizers(self) -> torch.optim.Optimizer:
        return make_optimizer(self.net.parameters(), self.train_config())

    def forward(self, x_selected: torch.Tensor) -> torch.Tensor:
        """(B, len(features)) float32 -> (B,) predicted distortion in (0, 1)."""
        return self.net(x_selected)

    def _predict(self, x: torch.Tensor) -> torch.Tensor:
        """(B, F) all data features -> (B,) prediction from the selected columns."""
        return self(x.index_select(1, self.feature_index.to(x.device)))

    # ------------------------------------------------------------ training
    def on_train_start(self) -> None:
        torch.manual_seed(int(self.hparams.seed))  # dropout masks, as lit3d.quality.trainer.fit_mlp_many

    def training_step(self, batch: dict, batch_idx: int) -> torch.Tensor:
        loss = F.mse_loss(self._predict(batch["x"]), batch["y"])
        self.log("train/mse", loss, on_step=False, on_epoch=True, batch_size=batch["y"].shape[0])
        return loss

    # ------------------------------------------------------------ validation / test
    def validation_step(self, batch: dict, batch_idx: int) -> None:
        pred = self._predict(batch["x"])
        self.val_corr.update(pred, batch["y"], batch["shape_id"])
        self.log("val/mse", F.mse_loss(pred, batch["y"]), batch_size=batch["y"].shape[0], sync_dist=True)

    def on_validation_epoch_end(self) -> None:
        # computed from the states of every rank: the same numbers on each, nothing to reduce
        values = self.val_corr.compute()
        self.val_corr.reset()
        self.log_dict({f"val/{k}": v for k, v in values.items() if "/" not in k})

    def test_step(self, batch: dict, batch_idx: int) -> None:
        self.test_corr.update(self._predict(batch["x"]), batch["y"], batch["shape_id"])

    def on_test_epoch_end(self) -> None:
        values = {f"test/ours/{k}": v for k, v in self.test_corr.compute().items()}
        self.test_corr.reset()
        self.log_dict({**values, "test/n_features": float(len(self.features))})

    # ------------------------------------------------------------ checkpoint
    def quality_meta(self) -> dict:
        return {"features": list(self.features), "net": dict(self.net_kwargs),
                "scaling": self.scaling.to_dict() if self.scaling else None, "sfs": self.sfs_info,
                "dataset": self.dataset_name, "feature_options": self.feature_options}

    def on_save_checkpoint(self, checkpoint: dict) -> None:
        checkpoint[CKPT_KEY] = self.quality_meta()

    def on_load_checkpoint(self, checkpoint: dict) -> None:
        meta = checkpoint.get(CKPT_KEY)
        if not meta:
            raise KeyError("not a quality checkpoint (no 'quality' entry with the selected features)")
        self.features = list(meta["features"])
        self.net_kwargs = dict(meta.get("net") or self.net_kwargs)
        self.scaling = TargetScaling.from_dict(meta["scaling"]) if meta.get("scaling") else None
        self.sfs_info = meta.get("sfs")
        self.dataset_name = meta.get("dataset")
        self.feature_options = meta.get("feature_options")
        self.net = QualityMLP(len(self.features), **self.net_kwargs)

    # ------------------------------------------------------------ summary
    @staticmethod
    def summary_rows(kwargs: dict) -> list[dict]:
        """Per-component rows for ``lit3d-summary`` (input width = ``features`` or 64 as an example)."""
        net_kw = {**NET_DEFAULTS, **dict(kwargs.get("net") or {})}
        n_in = len(kwargs.get("features") or []) or 64
        net = QualityMLP(n_in, **net_kw)
        return [{"component": "quality_mlp", "params": count_parameters(net), "input": f"(1, {n_in})",
                 "output": "(1,)"}]
