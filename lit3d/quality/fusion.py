"""A regularised fusion of quality features that survives a few dozen rated stimuli.

Beside the thesis's MLP + SFS (:class:`lit3d.quality.protocol.LearnedScore`), a linear model of
a priori oriented features (every feature multiplied by its sign so that higher = better, then
standardised on the training rows): ridge regression with **non-negative** weights (``ridge``, the
one kind), so every oriented feature may only raise the predicted quality and 27 training stimuli
cannot learn a sign that contradicts the measure's meaning. It is the minimiser of scikit-learn's
``Ridge(positive=True)`` (tested), solved as non-negative least squares of the augmented system
``[X; sqrt(alpha) I] w = [y; 0]`` with ``scipy.optimize.nnls`` on centred data: scikit-learn runs
L-BFGS-B there, about 400 times slower, and the nested protocol fits thousands of these. (A linear
SVR was a second kind until its weights were found to take signs against the measures' meaning and
to move with the target's offset, liblinear regularising the intercept: ``studies/quality/LOG.md``.)

The regularisation strength is chosen by leave-one-group-out inside the training rows (groups:
the distortion family or the reference shape; the pooled Spearman of the inner out-of-fold
predictions), so :func:`nested_group_out` (outer leave-one-group-out, inner choice of the model
kind and its strength) never looks at the held-out group.

A second kind, :class:`AnchoredFusion`, keeps one published measure (the anchor, e.g. PCQM) as the
scale of its score and learns only non-negative corrections in the anchor's units; its strength may
be infinite (the anchor alone). Its score is not re-centred or re-scaled per training fold, so the
out-of-fold scores of different folds stay on one scale, as a published measure's values do; the
opinion scale is a separate linear map of that score. (Round 1 of ``studies/quality/LOG.md``: a linear
map fitted per fold loses the order between the held-out families, even for one measure alone.)

A fitted model is a plain linear map, kept as JSON (:meth:`LinearFusion.to_dict`,
:meth:`AnchoredFusion.to_dict`, read back by :func:`fusion_from_dict`): the package's shipped
quality model (:mod:`lit3d.quality.shipped`) is one.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import math

import numpy as np

from lit3d.features.matrix import FeatureMatrix
from lit3d.quality.correlation import spearman
from lit3d.quality.opinion_map import apply_opinion_map, check_opinion_map, fit_opinion_map

KINDS = ("ridge",)
STRENGTHS = {"ridge": (0.1, 0.3, 1.0, 3.0, 10.0, 30.0, 100.0)}
STRENGTHS["anchored"] = STRENGTHS["ridge"] + (math.inf,)  # inf: the anchor alone, no correction


class PositiveRidge:
    """``min ||y - X w - b||^2 + alpha ||w||^2`` with ``w >= 0`` (``coef_`` (F,), ``intercept_``), fitted as NNLS."""

    def __init__(self, alpha: float):
        self.alpha = float(alpha)

    def fit(self, x: np.ndarray, y: np.ndarray) -> PositiveRidge:
        from scipy.optimize import nnls

        x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
        xm, ym = x.mean(0), y.mean()
        f = x.shape[1]
        a = np.vstack([x - xm, np.sqrt(self.alpha) * np.eye(f)])
        self.coef_ = nnls(a, np.concatenate([y - ym, np.zeros(f)]))[0]
        self.intercept_ = float(ym - xm @ self.coef_)
        return self


def _estimator(kind: str, strength: float) -> PositiveRidge:
    """The regressor of ``kind`` at ``strength`` (ridge: alpha)."""
    if kind == "ridge":
        return PositiveRidge(strength)
    raise ValueError(f"unknown fusion kind '{kind}' (use one of {KINDS})")


@dataclass
class LinearFusion:
    """Oriented, standardised features -> predicted distortion (the target's orientation: higher = worse).

    Attributes:
        features: F feature names; ``signs``: (F,) +1 when a larger value means better quality.
        kind: ``ridge``; ``strength``: its regularisation (None: chosen in :meth:`fit`).
        mean, scale: (F,) standardisation of the oriented features (set by :meth:`fit`).
        coef: (F,) weights of the standardised oriented features on *quality*, ``1 - target`` (the [0, 1]
            opinion scale, higher = better); ``intercept``: its constant.
    """

    features: Sequence[str]
    signs: Sequence[float]
    kind: str = "ridge"
    strength: float | None = None
    mean: np.ndarray | None = None
    scale: np.ndarray | None = None
    coef: np.ndarray | None = None
    intercept: float = 0.0
    inner: dict[str, float] = field(default_factory=dict)

    @property
    def inputs(self) -> list[str]:
        """Every feature the model reads, in the order :meth:`quality` takes them."""
        return list(self.features)

    units = None  # :meth:`predict` is on the opinion scale of its own fit: no units shared between fits

    def _oriented(self, fm: FeatureMatrix) -> np.ndarray:
        return fm.columns(list(self.features)) * np.asarray(self.signs, dtype=np.float64)

    def _fit_at(self, train: FeatureMatrix, strength: float):
        x = self._oriented(train)
        mean, scale = x.mean(0), x.std(0)
        scale = np.where(scale > 0, scale, 1.0)
        est = _estimator(self.kind, strength).fit((x - mean) / scale, 1.0 - train.target)
        return mean, scale, np.asarray(est.coef_, dtype=np.float64).ravel(), float(np.ravel(est.intercept_)[0])

    def fit(self, train: FeatureMatrix) -> LinearFusion:
        """Fit on ``train``; with ``strength=None`` choose it first by leave-one-group-out inside ``train``."""
        if self.strength is None:
            strength, self.inner = _choose_strength(
                train, lambda s: LinearFusion(self.features, self.signs, self.kind, s), STRENGTHS[self.kind])
        else:
            strength = float(self.strength)
        self.mean, self.scale, self.coef, self.intercept = self._fit_at(train, strength)
        self.strength = strength
        return self

    def quality(self, x: np.ndarray) -> np.ndarray:
        """Predicted quality ``1 - target`` (the [0, 1] scale, higher = better) of raw ``(N, F)`` feature rows."""
        if self.coef is None:
            raise RuntimeError("LinearFusion used before fit")
        z = (np.asarray(x, dtype=np.float64) * np.asarray(self.signs) - self.mean) / self.scale
        return z @ self.coef + self.intercept

    def predict(self, test: FeatureMatrix) -> np.ndarray:
        """Predicted distortion (the target's orientation, ``1 - quality``) of every row of ``test``: ``(N,)``."""
        return 1.0 - self.quality(test.columns(list(self.features)))

    def describe(self) -> dict:
        return {"kind": self.kind, "strength": self.strength,
                "weights": dict(zip(self.features, np.round(self.coef, 4).tolist())) if self.coef is not None else {}}

    def to_dict(self) -> dict[str, Any]:
        """JSON-able parameters (see :meth:`from_dict`)."""
        if self.coef is None:
            raise RuntimeError("LinearFusion.to_dict before fit")
        return {"kind": self.kind, "strength": self.strength, "features": list(self.features),
                "signs": [float(s) for s in self.signs], "mean": self.mean.tolist(), "scale": self.scale.tolist(),
                "coef": self.coef.tolist(), "intercept": self.intercept}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> LinearFusion:
        f = len(d["features"])
        arrays = {k: np.asarray(d[k], dtype=np.float64) for k in ("signs", "mean", "scale", "coef")}
        bad = [k for k, v in arrays.items() if v.shape != (f,) or not np.isfinite(v).all()]
        if bad or not np.isfinite(d["intercept"]):
            raise ValueError(f"fusion model: {bad or ['intercept']} do not hold {f} finite values")
        return cls(list(d["features"]), arrays["signs"].tolist(), d["kind"], d["strength"], arrays["mean"],
                   arrays["scale"], arrays["coef"], float(d["intercept"]))


def _choose_strength(train: FeatureMatrix, make: Callable[[float], Any], strengths) -> tuple[float, dict]:
    """The strength of ``strengths`` with the best :func:`inner_score` of ``make(strength)`` on ``train``
    (the smallest of equals) and every strength's inner score."""
    inner = {str(s): inner_score(train, lambda s=s: make(s)) for s in strengths}
    best = max(inner.values())
    return min(float(s) for s, v in inner.items() if v >= best - 1e-12), inner


@dataclass
class AnchoredFusion:
    """A published measure plus non-negative corrections in its units: ``score = sign_a * a + corrections . x``.

    ``x`` are the raw oriented correction features (each times its sign: higher = better), ``a`` the raw
    anchor. Fitting regresses quality on ``[a, x]`` (standardised, the anchor unpenalised, every weight
    >= 0) at ``strength`` and divides the corrections by the anchor's weight, so the score keeps the
    anchor's scale with no per-fold centring; ``strength`` inf (or an anchor weight of 0) is the anchor
    alone. Quality on the [0, 1] opinion scale is a monotone map of the score fitted on the training rows
    (:mod:`lit3d.quality.opinion_map`: the VQEG's four-parameter logistic, or a line). :meth:`predict`
    returns ``-score`` (the target's orientation); the out-of-fold scores of different folds are on the anchor's one scale.

    Attributes:
        anchor, anchor_sign: the anchor feature and its orientation (+1: higher is better).
        features, signs: F correction features and their orientations; ``corrections``: (F,) >= 0.
        strength: ridge strength of the corrections (None: chosen by inner leave-one-group-out).
        opinion: the opinion map of the score (:func:`lit3d.quality.opinion_map.fit_opinion_map`).
    """

    anchor: str
    anchor_sign: float
    features: Sequence[str]
    signs: Sequence[float]
    strength: float | None = None
    corrections: np.ndarray | None = None
    opinion: dict | None = None
    inner: dict[str, float] = field(default_factory=dict)
    kind: str = "anchored"
    _scored: tuple | None = field(default=None, repr=False, compare=False)  # (scores, quality) of the fit

    @property
    def inputs(self) -> list[str]:
        """Every feature the model reads: the anchor, then the corrections."""
        return [self.anchor, *self.features]

    def _score(self, x: np.ndarray) -> np.ndarray:
        """``(N,)`` scores of raw ``(N, 1 + F)`` rows of :attr:`inputs`."""
        x = np.asarray(x, dtype=np.float64)
        return self.anchor_sign * x[:, 0] + (x[:, 1:] * np.asarray(self.signs)) @ self.corrections

    def _corrections_at(self, a: np.ndarray, x: np.ndarray, q: np.ndarray, strength: float) -> np.ndarray:
        if math.isinf(strength) or x.shape[1] == 0:
            return np.zeros(x.shape[1])
        z = np.column_stack([a, x])
        sd = z.std(0)
        sd = np.where(sd > 0, sd, 1.0)
        zc, qc = (z - z.mean(0)) / sd, q - q.mean()
        pen = np.sqrt(strength) * np.eye(z.shape[1])
        pen[0, 0] = 0.0  # the anchor's weight is not shrunk
        from scipy.optimize import nnls

        w = nnls(np.vstack([zc, pen]), np.concatenate([qc, np.zeros(z.shape[1])]))[0] / sd
        return w[1:] / w[0] if w[0] > 0 else np.zeros(x.shape[1])

    def fit(self, train: FeatureMatrix) -> AnchoredFusion:
        """Fit on ``train``; with ``strength=None`` choose it first by leave-one-group-out inside ``train``."""
        if self.strength is None:
            strength, self.inner = _choose_strength(
                train, lambda s: AnchoredFusion(self.anchor, self.anchor_sign, self.features, self.signs, s),
                STRENGTHS["anchored"])
        else:
            strength = float(self.strength)
        cols = train.columns(self.inputs)
        a = self.anchor_sign * cols[:, 0]
        x = cols[:, 1:] * np.asarray(self.signs, dtype=np.float64)
        q = 1.0 - train.target
        self.corrections = self._corrections_at(a, x, q, strength)
        self.opinion, self._scored = None, (self._score(cols), q)  # the map is fitted when first needed
        self.strength = strength
        return self

    def quality(self, x: np.ndarray) -> np.ndarray:
        """Predicted quality ``1 - target`` (the [0, 1] opinion scale) of raw ``(N, 1 + F)`` rows of :attr:`inputs`."""
        if self.corrections is None:
            raise RuntimeError("AnchoredFusion used before fit")
        return apply_opinion_map(self._opinion(), self._score(x))

    def _opinion(self) -> dict:
        """The opinion map, fitted on the training scores at the first call (ranking needs none: the nested
        protocol's thousands of inner fits never pay for it)."""
        if self.opinion is None and self._scored is not None:
            self.opinion = fit_opinion_map(*self._scored)
        return self.opinion

    @property
    def units(self) -> str:
        """The units of :meth:`predict`: the anchor's, shared by every fit of this anchor."""
        return f"anchor:{self.anchor}"

    def predict(self, test: FeatureMatrix) -> np.ndarray:
        """``(N,)`` minus the score of every row of ``test`` (the target's orientation, on the anchor's scale)."""
        if self.corrections is None:
            raise RuntimeError("AnchoredFusion used before fit")
        return -self._score(test.columns(self.inputs))

    def describe(self) -> dict:
        alone = self.strength is not None and math.isinf(self.strength)
        return {"kind": self.kind, "anchor": self.anchor, "strength": "inf: the anchor alone" if alone else self.strength,
                "corrections": dict(zip(self.features, np.round(self.corrections, 6).tolist()))
                if self.corrections is not None else {}}

    def to_dict(self) -> dict[str, Any]:
        """JSON-able parameters (see :meth:`from_dict`); an infinite strength is written as None."""
        if self.corrections is None:
            raise RuntimeError("AnchoredFusion.to_dict before fit")
        return {"kind": self.kind, "anchor": self.anchor, "anchor_sign": float(self.anchor_sign),
                "strength": None if math.isinf(self.strength) else self.strength, "features": list(self.features),
                "signs": [float(s) for s in self.signs], "corrections": self.corrections.tolist(),
                "opinion": self._opinion()}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> AnchoredFusion:
        f = len(d["features"])
        arrays = {k: np.asarray(d[k], dtype=np.float64) for k in ("signs", "corrections")}
        bad = [k for k, v in arrays.items() if v.shape != (f,) or not np.isfinite(v).all()]
        if bad or not np.isfinite(float(d["anchor_sign"])):
            raise ValueError(f"anchored fusion model: {bad or ['anchor_sign']} do not hold finite values for "
                             f"{f} corrections")
        check_opinion_map(d["opinion"])
        strength = math.inf if d["strength"] is None else float(d["strength"])
        return cls(str(d["anchor"]), float(d["anchor_sign"]), list(d["features"]), arrays["signs"].tolist(),
                   strength, arrays["corrections"], dict(d["opinion"]))


def fusion_from_dict(d: Mapping[str, Any]) -> LinearFusion | AnchoredFusion:
    """A fitted fusion model from its :meth:`to_dict` form, by its ``kind``."""
    return AnchoredFusion.from_dict(d) if d.get("kind") == "anchored" else LinearFusion.from_dict(d)


def out_of_group(fm: FeatureMatrix, factory: Callable[[], Any]) -> np.ndarray:
    """``(N,)`` predictions of ``factory()`` models, each fitted without one group (``fm.shapes``) and
    predicting that group (leave-one-group-out)."""
    pred = np.zeros(len(fm))
    for g in fm.shape_names:
        rows = fm.shapes == g
        pred[rows] = factory().fit(fm.without_shape(g)).predict(fm.rows(rows))
    return pred


def inner_score(train: FeatureMatrix, factory: Callable[[], Any]) -> float:
    """Pooled Spearman of leave-one-group-out predictions inside ``train`` with the target (higher = better);
    with one group only, leave-one-row-out."""
    if len(train.shape_names) < 2:
        train = FeatureMatrix(train.X, train.names, np.array([str(i) for i in range(len(train))]), train.target,
                              train.items, train.dataset, train.target_name)
    return spearman(out_of_group(train, factory), train.target)


@dataclass
class ChosenFusion:
    """A model kind and strength chosen by :func:`inner_score` among ``candidates`` (name -> factory of an
    unfitted method), then fitted on all training rows; ``scores`` holds each candidate's inner score."""

    candidates: Mapping[str, Callable[[], Any]]
    chosen: str | None = None
    model: Any = None
    scores: dict[str, float] = field(default_factory=dict)

    def fit(self, train: FeatureMatrix) -> ChosenFusion:
        self.scores = {name: inner_score(train, f) for name, f in self.candidates.items()}
        self.chosen = max(self.scores, key=lambda k: self.scores[k])  # first of equals: candidates' order
        self.model = self.candidates[self.chosen]().fit(train)
        return self

    def predict(self, test: FeatureMatrix) -> np.ndarray:
        return self.model.predict(test)


def nested_group_out(fm: FeatureMatrix, candidates: Mapping[str, Callable[[], Any]]) -> tuple[np.ndarray, dict]:
    """Outer leave-one-group-out; in each outer fold the candidate (and each linear model's strength) is
    chosen by leave-one-group-out inside the other groups. Returns the ``(N,)`` out-of-fold predictions
    (target orientation) and ``{group: {"chosen", "scores", "described", "units"}}``.

    The pooled predictions must share units: when every fold chose a model of the same ``units`` (an
    anchored fusion's anchor) they are the models' :meth:`predict` (on that anchor's scale); otherwise each fold's
    predicted opinion (``1 - model.quality``, its own opinion map), the one scale every kind has."""
    raw, opinion = np.zeros(len(fm)), np.zeros(len(fm))
    choices, scales = {}, set()
    for g in fm.shape_names:
        rows = fm.shapes == g
        chosen = ChosenFusion(candidates).fit(fm.without_shape(g))
        test, model = fm.rows(rows), chosen.model
        raw[rows] = chosen.predict(test)
        opinion[rows] = 1.0 - model.quality(test.columns(model.inputs)) if hasattr(model, "quality") else raw[rows]
        units = getattr(model, "units", None)
        scales.add(units)
        choices[g] = {"chosen": chosen.chosen, "scores": chosen.scores, "units": units or "opinion",
                      "described": model.describe() if hasattr(model, "describe") else {}}
    shared = len(scales) == 1 and None not in scales
    return (raw if shared else opinion), choices
