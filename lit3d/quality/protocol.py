"""Evaluation protocol of thesis ch. 4 on a plain feature matrix.

A :class:`FeatureMatrix` is one dataset: ``N`` mesh pairs (reference, distorted)
grouped by reference shape, ``F`` named features per pair, and one target per
pair. Everything here works on it and on nothing else (no rendering, no files):

- :func:`fit_mlp_many` / :func:`fit_mlp` train the thesis MLP (``lit3d.quality.nets``)
  with the thesis's optimiser (SGD, MSE, batch 3); the many-model form trains the
  candidate models of one Sequential Forward Search step together.
- :func:`training_corr` builds Algorithm 4.1's ``corr(.)`` bound to training data.
- Methods (``fit(train) -> self``, ``predict(test) -> (N,)``): :class:`LearnedScore`
  (all features = thesis "Our", SFS = "Our*"), :class:`FeatureBaseline` (one fixed
  measure with a fixed sign: Chamfer, Hausdorff, MSE, PSNR, MS-SSIM),
  :class:`SingleBestFeature` (the one feature, and its sign, with the best training
  correlation).
- :func:`leave_one_shape_out` and :func:`cross_dataset`: Pearson and Spearman per
  test shape and averaged over shapes.

Targets are oriented "higher = more distorted" and scaled to [0, 1] per dataset
(:func:`scale_targets`); baselines are oriented the same way (distances as they
are, similarities negated), so every correlation below reads "higher is better".
"""
from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from lit3d.features.matrix import FeatureMatrix, TargetScaling, clip_nonfinite, scale_targets  # noqa: F401
from lit3d.quality.correlation import mean_per_shape_corr, pearson, per_shape_corr, spearman  # noqa: F401
from lit3d.quality.trainer import TrainConfig, fit_mlp, fit_mlp_many, predict, predict_many, training_corr  # noqa: F401
from lit3d.quality.nets import QualityMLP
from lit3d.quality.selection import SFSResult, sequential_forward_search


# --------------------------------------------------------------------------- methods
class Method(Protocol):
    def fit(self, train: FeatureMatrix) -> Method: ...

    def predict(self, test: FeatureMatrix) -> np.ndarray: ...


@dataclass
class FeatureBaseline:
    """One measure used as the score: ``sign * X[:, feature]`` (sign -1 for similarities)."""

    feature: str
    sign: float = 1.0

    def fit(self, train: FeatureMatrix) -> FeatureBaseline:
        return self

    def predict(self, test: FeatureMatrix) -> np.ndarray:
        return self.sign * test.columns([self.feature])[:, 0]

    def describe(self) -> dict:
        return {"feature": self.feature, "sign": self.sign}


@dataclass
class SingleBestFeature:
    """The feature (and sign) with the highest training correlation, chosen on the training folds."""

    kind: str = "pearson"
    candidates: Sequence[str] | None = None
    feature: str | None = None
    sign: float = 1.0

    def fit(self, train: FeatureMatrix) -> SingleBestFeature:
        names = list(self.candidates) if self.candidates is not None else train.names
        best, best_val = None, -math.inf
        for name in names:
            r = mean_per_shape_corr(train.columns([name])[:, 0], train.target, train.shapes, self.kind)
            if abs(r) > best_val:
                best, best_val, sign = name, abs(r), (1.0 if r >= 0 else -1.0)
        if best is None:
            raise ValueError("SingleBestFeature: no candidate features")
        self.feature, self.sign = best, sign
        return self

    def predict(self, test: FeatureMatrix) -> np.ndarray:
        if self.feature is None:
            raise RuntimeError("SingleBestFeature.predict before fit")
        return self.sign * test.columns([self.feature])[:, 0]

    def describe(self) -> dict:
        return {"feature": self.feature, "sign": self.sign}


@dataclass
class LearnedScore:
    """The thesis model: (optional SFS on the training data) + MLP trained on the training data.

    selection: "sfs" (thesis "Our*") or "all" (thesis "Our").
    candidates: restrict the features (e.g. to the Mask-SSIM variant of a sweep point).
    """

    cfg: TrainConfig = field(default_factory=TrainConfig)
    selection: str = "sfs"
    criterion: str = "train"
    sfs_kind: str = "pearson"
    max_features: int | None = None
    min_gain: float = 0.0
    candidates: Sequence[str] | None = None
    sfs_cfg: TrainConfig | None = None  # training set-up of the SFS scorer (default: cfg)
    # set by fit
    features: list[str] = field(default_factory=list)
    sfs: SFSResult | None = None
    net: QualityMLP | None = None

    def select_features(self, train: FeatureMatrix) -> list[str]:
        names = [n for n in (self.candidates if self.candidates is not None else train.names) if n in train.names]
        if not names:
            raise ValueError(f"{train.dataset}: none of the candidate features are in the feature matrix")
        if self.selection == "all":
            self.sfs = None
            return names
        if self.selection != "sfs":
            raise ValueError(f"unknown selection '{self.selection}' (sfs | all)")
        corr = training_corr(train, self.sfs_cfg or self.cfg, self.criterion, self.sfs_kind)
        self.sfs = sequential_forward_search(names, corr, self.max_features, self.min_gain)
        return self.sfs.selected

    def fit(self, train: FeatureMatrix) -> LearnedScore:
        self.features = self.select_features(train)
        self.net = fit_mlp(train.columns(self.features), train.target, self.cfg)
        return self

    def predict(self, test: FeatureMatrix) -> np.ndarray:
        if self.net is None:
            raise RuntimeError("LearnedScore.predict before fit")
        return predict(self.net, test.columns(self.features))

    def describe(self) -> dict:
        return {"features": list(self.features), "sfs": self.sfs.to_dict() if self.sfs else None}


# Thesis baselines (tables 4.2-4.4): measure -> (feature name, sign). Image measures on
# the flat-shaded ceramic-lightbulb renders, as the thesis's MS-SSIM set-up.
DEFAULT_BASELINES: dict[str, tuple[str, float]] = {
    "chamfer": ("chamfer", 1.0),
    "hausdorff": ("hausdorff", 1.0),
    "mse": ("mse/ceramic_lightbulb/flat", 1.0),
    "psnr": ("psnr/ceramic_lightbulb/flat", -1.0),
    "ms_ssim": ("ms_ssim/ceramic_lightbulb/flat", -1.0),
}


def baseline_methods(names: Sequence[str], baselines: Mapping[str, tuple[str, float]] | None = None,
                     single_best: bool = True) -> dict[str, Method]:
    """The baselines whose features exist in ``names`` (+ the single best feature)."""
    baselines = DEFAULT_BASELINES if baselines is None else baselines
    have = set(names)
    out: dict[str, Method] = {k: FeatureBaseline(f, float(s)) for k, (f, s) in baselines.items() if f in have}
    if single_best:
        out["single_best"] = SingleBestFeature()
    return out


# --------------------------------------------------------------------------- protocol
@dataclass
class ShapeResult:
    pearson: float
    spearman: float
    target: np.ndarray
    pred: np.ndarray
    info: dict = field(default_factory=dict)


@dataclass
class EvalResult:
    """One method's per-shape correlations (+ their means over shapes)."""

    method: str
    per_shape: dict[str, ShapeResult]

    @property
    def mean_pearson(self) -> float:
        return float(np.mean([r.pearson for r in self.per_shape.values()])) if self.per_shape else float("nan")

    @property
    def mean_spearman(self) -> float:
        return float(np.mean([r.spearman for r in self.per_shape.values()])) if self.per_shape else float("nan")

    def metrics(self, prefix: str) -> dict[str, float]:
        """``{prefix}/{method}/pearson/{shape}``, ... and ``.../pearson`` (mean over shapes)."""
        out: dict[str, float] = {}
        for kind in ("pearson", "spearman"):
            for shape, r in self.per_shape.items():
                out[f"{prefix}/{self.method}/{kind}/{shape}"] = float(getattr(r, kind))
            out[f"{prefix}/{self.method}/{kind}"] = self.mean_pearson if kind == "pearson" else self.mean_spearman
        return out


def _score(method_name: str, method: Method, test: FeatureMatrix) -> dict[str, ShapeResult]:
    pred = np.asarray(method.predict(test), dtype=np.float64)
    info = method.describe() if hasattr(method, "describe") else {}
    out = {}
    for shape in test.shape_names:
        m = test.shapes == shape
        out[shape] = ShapeResult(pearson(pred[m], test.target[m]), spearman(pred[m], test.target[m]),
                                 test.target[m].copy(), pred[m].copy(), info)
    return out


MethodFactory = Callable[[], Method]


def leave_one_shape_out(fm: FeatureMatrix, methods: Mapping[str, MethodFactory],
                        shapes: Sequence[str] | None = None,
                        on_fold: Callable[[str, str, Method], None] | None = None) -> dict[str, EvalResult]:
    """Each shape in turn is the test shape; every method is fitted (incl. feature
    selection) on the other shapes only and scored on the held-out one.

    methods: name -> factory making a fresh, unfitted method. Returns name -> result.
    """
    shapes = list(shapes) if shapes is not None else fm.shape_names
    if len(fm.shape_names) < 2:
        raise ValueError(f"{fm.dataset}: leave-one-shape-out needs at least two shapes, has {fm.shape_names}")
    results = {name: EvalResult(name, {}) for name in methods}
    for shape in shapes:
        train, test = fm.without_shape(shape), fm.only_shape(shape)
        for name, factory in methods.items():
            method = factory().fit(train)
            if on_fold is not None:
                on_fold(shape, name, method)
            results[name].per_shape.update(_score(name, method, test))
    return results


def cross_dataset(train: FeatureMatrix, tests: Mapping[str, FeatureMatrix],
                  methods: Mapping[str, MethodFactory]) -> dict[str, dict[str, EvalResult]]:
    """Select + train on all of ``train``; test per shape on each other dataset (table 4.8).

    Only features present in every dataset are candidates. Returns dataset -> method -> result.
    """
    common = [n for n in train.names if all(n in t.names for t in tests.values())]
    if not common:
        raise ValueError("cross_dataset: the datasets share no feature names")
    train_c = train.select(common)
    out: dict[str, dict[str, EvalResult]] = {name: {} for name in tests}
    for mname, factory in methods.items():
        method = factory().fit(train_c)
        for dname, test in tests.items():
            out[dname][mname] = EvalResult(mname, _score(mname, method, test.select(common)))
    return out


def results_to_metrics(results: Mapping[str, EvalResult], prefix: str) -> dict[str, float]:
    out: dict[str, float] = {}
    for res in results.values():
        out.update(res.metrics(prefix))
    return out
