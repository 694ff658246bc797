"""Rendering-based shape quality (thesis ch. 4) as a LightningModule.

Batches come from ``datamodules.quality``:
    x     (B, F) float32   every feature of the pair (the datamodule's ``feature_names``)
    y     (B,)   float32   target in [0, 1], higher = more distorted (MOS or ordinal severity)
    shape list[str], item list[str]

At ``setup("fit")`` the task chooses its input features on the *training split only*
(Sequential Forward Search, Algorithm 4.1, or all features) and builds the thesis
MLP for them; it trains with MSE and SGD (thesis: lr 1e-4, batch 3, 250 epochs).
The checkpoint stores the selected feature names and the target scaling
(``checkpoint["quality"]``, plain values) so ``lit3d.quality.predict`` and
``lit3d-score --ckpt`` can use it without the data.

Logged: ``val/pearson``, ``val/spearman`` (mean over validation shapes); on test,
per test shape and averaged, for the model (``test/ours/...``) and the baselines
fitted/selected on the training split (``test/<baseline>/...``). With
``cv=True`` the test also runs the whole leave-one-shape-out protocol of tables
4.2-4.4 on the datamodule's full matrix (``test/cv/<method>/<kind>[/<shape>]``),
and with ``cross_data`` the cross-dataset protocol of table 4.8
(``test/cross/<dataset>/<method>/...``).
"""
from __future__ import annotations

import fnmatch
from collections.abc import Mapping, Sequence
from typing import Any

import lightning.pytorch as pl
import numpy as np
import torch
import torch.nn.functional as F

from lit3d.nets.quality import QualityMLP, count_parameters
from lit3d.quality.protocol import (
    FeatureMatrix,
    LearnedScore,
    TargetScaling,
    TrainConfig,
    baseline_methods,
    cross_dataset,
    leave_one_shape_out,
    pearson,
    results_to_metrics,
    spearman,
)
from lit3d.quality.protocol import training_corr
from lit3d.quality.selection import sequential_forward_search

CKPT_KEY = "quality"


def filter_features(names: Sequence[str], include: Sequence[str] | None, exclude: Sequence[str] | None) -> list[str]:
    """Feature names matching any ``include`` glob (all if None) and no ``exclude`` glob."""
    out = [n for n in names if include is None or any(fnmatch.fnmatchcase(n, p) for p in include)]
    return [n for n in out if not exclude or not any(fnmatch.fnmatchcase(n, p) for p in exclude)]


class QualityTask(pl.LightningModule):
    """Thesis MLP on (selected) rendering features, predicting distortion in [0, 1]."""

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
        baselines: Mapping[str, Sequence] | None = None,
        cv: bool = False,
        cv_epochs: int | None = None,
        cv_methods: Sequence[str] = ("ours_all", "ours_sfs"),
        cross_data: Sequence[Mapping[str, Any]] | None = None,
        seed: int = 0,
    ):
        super().__init__()
        self.save_hyperparameters()
        self.net_kwargs = {"hidden": 32, "blocks": 2, "dropout": 0.1, "batch_norm": True, **dict(net or {})}
        self.features: list[str] = list(features or [])
        self.feature_index: torch.Tensor | None = None
        self.scaling: TargetScaling | None = None
        self.sfs_info: dict | None = None
        self.dataset_name: str | None = None
        self.feature_options: dict | None = None
        self.net: QualityMLP | None = QualityMLP(len(self.features), **self.net_kwargs) if self.features else None
        self._outputs: dict[str, list] = {"val": [], "test": []}
        self.test_predictions: dict[str, dict] = {}
        self.cv_results: dict | None = None

    # ------------------------------------------------------------ config helpers
    def train_config(self, epochs: int | None = None) -> TrainConfig:
        hp = self.hparams
        if epochs is None:
            epochs = int(self.trainer.max_epochs) if self._trainer is not None and self.trainer.max_epochs else 250
        return TrainConfig(**{k: self.net_kwargs[k] for k in ("hidden", "blocks", "dropout", "batch_norm")},
                           optimizer=hp.optimizer, lr=hp.lr, momentum=hp.momentum, weight_decay=hp.weight_decay,
                           batch_size=self._batch_size(), epochs=int(epochs), seed=int(hp.seed))

    def _batch_size(self) -> int:
        dm = getattr(self._trainer, "datamodule", None) if self._trainer is not None else None
        return int(getattr(dm, "batch_size", 3) or 3)

    def sfs_config(self) -> dict:
        d = {"criterion": "train", "kind": "pearson", "max_features": None, "min_gain": 0.0, "epochs": None}
        d.update(dict(self.hparams.sfs or {}))
        return d

    def candidates(self, names: Sequence[str]) -> list[str]:
        cands = filter_features(names, self.hparams.include, self.hparams.exclude)
        if not cands:
            raise ValueError(f"no features match include={self.hparams.include} exclude={self.hparams.exclude}")
        return cands

    def learned_method(self, selection: str, names: Sequence[str], epochs: int | None = None) -> LearnedScore:
        """The protocol's form of this task (same net, optimiser, selection) for cross-validation."""
        s = self.sfs_config()
        cfg = self.train_config(epochs)
        sfs_cfg = None if s["epochs"] is None else TrainConfig(**{**cfg.__dict__, "epochs": int(s["epochs"])})
        return LearnedScore(cfg, selection, s["criterion"], s["kind"], s["max_features"], s["min_gain"],
                            candidates=self.candidates(names), sfs_cfg=sfs_cfg)

    # ------------------------------------------------------------ selection + net
    def select_features(self, train: FeatureMatrix) -> list[str]:
        """SFS (or all) on the training split only; sets ``self.sfs_info``."""
        cands = self.candidates(train.names)
        if self.hparams.selection == "all":
            self.sfs_info = None
            return cands
        if self.hparams.selection != "sfs":
            raise ValueError(f"unknown selection '{self.hparams.selection}' (sfs | all)")
        s = self.sfs_config()
        cfg = self.train_config(s["epochs"])
        corr = training_corr(train, cfg, s["criterion"], s["kind"])
        res = sequential_forward_search(cands, corr, s["max_features"], s["min_gain"])
        self.sfs_info = res.to_dict()
        return res.selected

    def setup(self, stage: str) -> None:
        dm = self.trainer.datamodule
        if dm is None:
            raise RuntimeError("QualityTask needs a datamodule (datamodules.quality.QualityDataModule)")
        dm.setup(stage)
        self.dataset_name = dm.name
        if self.feature_options is None:
            self.feature_options = dict(getattr(dm.hparams, "feature_options", None) or {}) if hasattr(dm, "hparams") else {}
        if self.scaling is None:
            self.scaling = dm.scaling
        if self.net is None:
            if stage != "fit":
                raise RuntimeError("QualityTask has no trained network: fit it or load a checkpoint")
            self.features = self.select_features(dm.split("train"))
            self.net = QualityMLP(len(self.features), **self.net_kwargs)
        self._set_index(dm.feature_names)

    def _set_index(self, names: Sequence[str]) -> None:
        pos = {n: i for i, n in enumerate(names)}
        missing = [f for f in self.features if f not in pos]
        if missing:
            raise KeyError(f"the data lacks {len(missing)} feature(s) this model uses, e.g. {missing[:3]}")
        self.feature_index = torch.tensor([pos[f] for f in self.features], dtype=torch.long)

    def forward(self, x_selected: torch.Tensor) -> torch.Tensor:
        """(B, len(features)) float32 -> (B,) predicted distortion in (0, 1)."""
        return self.net(x_selected)

    def _select(self, x: torch.Tensor) -> torch.Tensor:
        return x.index_select(1, self.feature_index.to(x.device))

    # ------------------------------------------------------------ training
    def configure_optimizers(self):
        hp = self.hparams
        if hp.optimizer == "sgd":
            return torch.optim.SGD(self.net.parameters(), lr=hp.lr, momentum=hp.momentum, weight_decay=hp.weight_decay)
        if hp.optimizer == "adam":
            return torch.optim.Adam(self.net.parameters(), lr=hp.lr, weight_decay=hp.weight_decay)
        raise ValueError(f"unknown optimizer '{hp.optimizer}' (sgd | adam)")

    def training_step(self, batch: dict, batch_idx: int) -> torch.Tensor:
        pred = self(self._select(batch["x"]))
        loss = F.mse_loss(pred, batch["y"])
        self.log("train/mse", loss, on_step=False, on_epoch=True, batch_size=batch["y"].shape[0])
        return loss

    def _collect(self, split: str, batch: dict) -> None:
        with torch.no_grad():
            pred = self(self._select(batch["x"]))
        self._outputs[split].append((pred.detach().cpu().double().numpy(), batch["y"].cpu().double().numpy(),
                                     list(batch["shape"]), list(batch["item"])))

    def _gather(self, split: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[str]]:
        outs = self._outputs[split]
        self._outputs[split] = []
        if not outs:
            return np.zeros(0), np.zeros(0), np.zeros(0, dtype=str), []
        pred = np.concatenate([o[0] for o in outs])
        y = np.concatenate([o[1] for o in outs])
        shapes = np.array([s for o in outs for s in o[2]])
        items = [i for o in outs for i in o[3]]
        return pred, y, shapes, items

    @staticmethod
    def _corr_metrics(prefix: str, pred: np.ndarray, y: np.ndarray, shapes: np.ndarray) -> dict[str, float]:
        out: dict[str, float] = {}
        for kind, fn in (("pearson", pearson), ("spearman", spearman)):
            vals = {s: fn(pred[shapes == s], y[shapes == s]) for s in dict.fromkeys(shapes.tolist())}
            out.update({f"{prefix}/{kind}/{s}": v for s, v in vals.items()})
            out[f"{prefix}/{kind}"] = float(np.mean(list(vals.values()))) if vals else float("nan")
        return out

    def validation_step(self, batch: dict, batch_idx: int) -> None:
        self._collect("val", batch)
        self.log("val/mse", F.mse_loss(self(self._select(batch["x"])), batch["y"]), batch_size=batch["y"].shape[0])

    def on_validation_epoch_end(self) -> None:
        pred, y, shapes, _ = self._gather("val")
        if len(pred):
            m = self._corr_metrics("val", pred, y, shapes)
            self.log_dict({k: v for k, v in m.items() if k.count("/") == 1}, sync_dist=False)

    # ------------------------------------------------------------ test
    def test_step(self, batch: dict, batch_idx: int) -> None:
        self._collect("test", batch)

    def on_test_epoch_end(self) -> None:
        pred, y, shapes, items = self._gather("test")
        dm = self.trainer.datamodule
        out: dict[str, float] = {}
        if len(pred):
            out.update(self._corr_metrics("test/ours", pred, y, shapes))
            self.test_predictions = {"ours": {"pred": pred, "target": y, "shapes": shapes, "items": items}}
            train, test = dm.split("train"), dm.split("test")
            for name, method in baseline_methods(test.names, self._baselines()).items():
                method.fit(train)
                bp = method.predict(test)
                out.update(self._corr_metrics(f"test/{name}", bp, test.target, test.shapes))
                self.test_predictions[name] = {"pred": bp, "target": test.target, "shapes": test.shapes,
                                               "items": test.items}
        out["test/n_features"] = float(len(self.features))
        if self.hparams.cv:
            out.update(self.run_cv(dm.matrix))
        if self.hparams.cross_data:
            out.update(self.run_cross(dm))
        self.log_dict(out, sync_dist=False)

    def _baselines(self) -> dict | None:
        b = self.hparams.baselines
        return None if b is None else {k: (str(v[0]), float(v[1])) for k, v in b.items()}

    def cv_methods(self, names: Sequence[str]) -> dict:
        epochs = self.hparams.cv_epochs
        methods = {}
        for key, selection in (("ours_all", "all"), ("ours_sfs", "sfs")):
            if key in self.hparams.cv_methods:
                methods[key] = lambda selection=selection: self.learned_method(selection, names, epochs)
        return methods

    def run_cv(self, fm: FeatureMatrix) -> dict[str, float]:
        """Leave-one-shape-out (tables 4.2-4.4) on the full matrix, model + baselines."""
        methods = dict(self.cv_methods(fm.names))
        for name in baseline_methods(fm.names, self._baselines()):
            methods[name] = lambda name=name: baseline_methods(fm.names, self._baselines())[name]
        results = leave_one_shape_out(fm, methods)
        self.cv_results = results
        return results_to_metrics(results, "test/cv")

    def run_cross(self, dm) -> dict[str, float]:
        """Select + train on this datamodule's full matrix; test on each ``cross_data`` dataset (table 4.8)."""
        from hydra.utils import instantiate
        from omegaconf import OmegaConf

        tests = {}
        for cfg in self.hparams.cross_data:
            other = instantiate(OmegaConf.create(dict(cfg)), _convert_="all")
            other.prepare_data()
            other.setup("test")
            tests[other.name] = other.matrix
        all_methods = self.cv_methods(dm.matrix.names)
        methods = {k: v for k, v in all_methods.items() if k == "ours_sfs"} or all_methods
        res = cross_dataset(dm.matrix, tests, methods)
        out: dict[str, float] = {}
        for dname, per_method in res.items():
            out.update(results_to_metrics(per_method, f"test/cross/{dname}"))
        return out

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
        net_kw = {"hidden": 32, "blocks": 2, "dropout": 0.1, "batch_norm": True, **dict(kwargs.get("net") or {})}
        n_in = len(kwargs.get("features") or []) or 64
        net = QualityMLP(n_in, **net_kw)
        return [{"component": "quality_mlp", "params": count_parameters(net), "input": f"(1, {n_in})",
                 "output": "(1,)"}]
