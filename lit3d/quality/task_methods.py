"""The quality task's settings (its hparams) and evaluation settings as protocol pieces: candidate
features, feature selection on a training split, the learned methods of cross-validation, the baselines.

Shared by :class:`lit3d.quality.feature_selection.FeatureSelection` (selection before fit) and
:func:`lit3d.quality.evaluator.protocol` (baselines, leave-one-shape-out, cross-dataset), so the
checkpoint's model and the protocol's "Our*" rows are chosen by the same code.
``hp`` is the task's ``hparams`` (``QualityTask.__init__`` arguments); ``cfg`` its
:class:`~lit3d.quality.trainer.TrainConfig` (``QualityTask.train_config``); which learned methods
cross-validation runs and the baselines are evaluation settings (the config's ``evaluation`` node:
``cv_methods``, ``baselines``), passed in by :mod:`lit3d.quality.evaluator`.
"""
from __future__ import annotations

import fnmatch
from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import Any

from lit3d.features.matrix import FeatureMatrix
from lit3d.quality.protocol import LearnedScore, MethodFactory
from lit3d.quality.trainer import TrainConfig

LEARNED_METHODS = {"ours_all": "all", "ours_sfs": "sfs"}  # protocol name -> selection


def filter_features(names: Sequence[str], include: Sequence[str] | None, exclude: Sequence[str] | None) -> list[str]:
    """Feature names matching any ``include`` glob (all if None) and no ``exclude`` glob."""
    out = [n for n in names if include is None or any(fnmatch.fnmatchcase(n, p) for p in include)]
    return [n for n in out if not exclude or not any(fnmatch.fnmatchcase(n, p) for p in exclude)]


def candidates(hp: Mapping[str, Any], names: Sequence[str]) -> list[str]:
    """The features the task may use (``include`` / ``exclude`` globs); ValueError if none."""
    cands = filter_features(names, hp["include"], hp["exclude"])
    if not cands:
        raise ValueError(f"no features match include={hp['include']} exclude={hp['exclude']}")
    return cands


def sfs_settings(hp: Mapping[str, Any]) -> dict:
    """``hp["sfs"]`` over the defaults (criterion, kind, max_features, min_gain, epochs)."""
    d = {"criterion": "train", "kind": "pearson", "max_features": None, "min_gain": 0.0, "epochs": None}
    d.update(dict(hp["sfs"] or {}))
    return d


def _sfs_cfg(hp: Mapping[str, Any], cfg: TrainConfig) -> TrainConfig | None:
    epochs = sfs_settings(hp)["epochs"]
    return None if epochs is None else replace(cfg, epochs=int(epochs))


def select_features(hp: Mapping[str, Any], train: FeatureMatrix, cfg: TrainConfig) -> tuple[list[str], dict | None]:
    """(selected feature names, SFS record or None) on the training split only: Sequential
    Forward Search (Algorithm 4.1) when ``hp["selection"] == "sfs"``, every candidate for "all".
    The protocol's own :meth:`LearnedScore.select_features`, with the task's settings."""
    method = learned_method(hp, cfg, hp["selection"], train.names)
    features = method.select_features(train)
    return features, method.sfs.to_dict() if method.sfs else None


def learned_method(hp: Mapping[str, Any], cfg: TrainConfig, selection: str, names: Sequence[str]) -> LearnedScore:
    """The protocol's form of the task (same net, optimiser, selection) for cross-validation."""
    s = sfs_settings(hp)
    return LearnedScore(cfg, selection, s["criterion"], s["kind"], s["max_features"], s["min_gain"],
                        candidates=candidates(hp, names), sfs_cfg=_sfs_cfg(hp, cfg))


def cv_methods(hp: Mapping[str, Any], cfg: TrainConfig, names: Sequence[str],
               methods: Sequence[str]) -> dict[str, MethodFactory]:
    """Factories of the learned ``methods`` (the evaluation setting ``cv_methods``: ours_all, ours_sfs)."""
    return {key: (lambda selection=selection: learned_method(hp, cfg, selection, names))
            for key, selection in LEARNED_METHODS.items() if key in methods}


def task_baselines(baselines: Mapping[str, Sequence] | None) -> dict[str, tuple[str, float]] | None:
    """The evaluation setting ``baselines`` as name -> (feature, sign), or None for the thesis's defaults."""
    return None if baselines is None else {k: (str(v[0]), float(v[1])) for k, v in baselines.items()}
