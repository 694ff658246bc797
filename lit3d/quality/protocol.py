"""Evaluation protocol of thesis ch. 4 on a plain feature matrix.

A :class:`FeatureMatrix` is one dataset: ``N`` mesh pairs (reference, distorted)
grouped by reference shape, ``F`` named features per pair, and one target per
pair. Everything here works on it and on nothing else (no rendering, no files):

- :func:`fit_mlp_many` / :func:`fit_mlp` train the thesis MLP (``lit3d.nets.quality``)
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
from dataclasses import dataclass, field, replace
from typing import Any, Protocol

import numpy as np
import torch

from lit3d.nets.quality import BatchedQualityMLP, QualityMLP
from lit3d.quality.selection import SFSResult, sequential_forward_search


# --------------------------------------------------------------------------- data
@dataclass
class FeatureMatrix:
    """One dataset as a matrix.

    X:       (N, F) float64, finite
    names:   F feature names (``measure/style/shading``, ``chamfer``, ...)
    shapes:  (N,) str, the reference shape of each pair (the cross-validation group)
    target:  (N,) float64, oriented higher = more distorted (usually scaled to [0, 1])
    items:   N pair ids (e.g. ``armadillo/noise_3``)
    dataset: dataset name; ``target_name`` says what the target is (e.g. "MOS",
             "ordinal severity score")
    """

    X: np.ndarray
    names: list[str]
    shapes: np.ndarray
    target: np.ndarray
    items: list[str] = field(default_factory=list)
    dataset: str = "dataset"
    target_name: str = "target"

    def __post_init__(self) -> None:
        self.X = np.asarray(self.X, dtype=np.float64)
        self.names = list(self.names)
        self.shapes = np.asarray(self.shapes).astype(str)
        self.target = np.asarray(self.target, dtype=np.float64)
        n = self.X.shape[0]
        if self.X.ndim != 2 or self.X.shape[1] != len(self.names):
            raise ValueError(f"{self.dataset}: X has shape {self.X.shape} but there are {len(self.names)} feature names")
        if len(set(self.names)) != len(self.names):
            raise ValueError(f"{self.dataset}: duplicate feature names")
        if self.shapes.shape != (n,) or self.target.shape != (n,):
            raise ValueError(f"{self.dataset}: {n} rows but {self.shapes.shape} shapes and {self.target.shape} targets")
        if not self.items:
            self.items = [f"{s}/{i}" for i, s in enumerate(self.shapes)]
        if len(self.items) != n:
            raise ValueError(f"{self.dataset}: {n} rows but {len(self.items)} item ids")
        bad = ~np.isfinite(self.X)
        if bad.any():
            col = self.names[int(np.nonzero(bad.any(0))[0][0])]
            raise ValueError(f"{self.dataset}: non-finite feature values (first in column '{col}'); "
                             "clean them with FeatureMatrix.from_tables(..., nonfinite='clip')")
        if not np.isfinite(self.target).all():
            raise ValueError(f"{self.dataset}: non-finite target values")

    # ---------------------------------------------------------------- building
    @classmethod
    def from_tables(cls, tables: Sequence[Mapping[str, float]], shapes: Sequence[str], target: Sequence[float],
                    items: Sequence[str] | None = None, names: Sequence[str] | None = None,
                    dataset: str = "dataset", target_name: str = "target", nonfinite: str = "clip") -> FeatureMatrix:
        """Stack per-pair feature dicts (``name -> float``) into a matrix.

        names: the columns (default: the names present in every table, sorted).
        nonfinite: "clip" replaces +-inf by the column's finite max/min (PSNR of identical
        renders is +inf) and NaN by the column median; "raise" refuses them.
        """
        if names is None:
            common = set(tables[0]) if tables else set()
            for t in tables[1:]:
                common &= set(t)
            names = sorted(common)
        missing = [(i, n) for i, t in enumerate(tables) for n in names if n not in t]
        if missing:
            i, n = missing[0]
            raise KeyError(f"{dataset}: feature '{n}' missing for item {items[i] if items else i}")
        X = np.array([[float(t[n]) for n in names] for t in tables], dtype=np.float64).reshape(len(tables), len(names))
        if nonfinite == "clip":
            X = clip_nonfinite(X)
        return cls(X, list(names), np.asarray(shapes), np.asarray(target, dtype=np.float64),
                   list(items) if items is not None else [], dataset, target_name)

    # ---------------------------------------------------------------- views
    @property
    def shape_names(self) -> list[str]:
        """Shapes in order of first appearance."""
        return list(dict.fromkeys(self.shapes.tolist()))

    def rows(self, mask: np.ndarray) -> FeatureMatrix:
        mask = np.asarray(mask)
        idx = np.nonzero(mask)[0] if mask.dtype == bool else mask
        return replace(self, X=self.X[idx], shapes=self.shapes[idx], target=self.target[idx],
                       items=[self.items[i] for i in idx])

    def columns(self, names: Sequence[str]) -> np.ndarray:
        """(N, len(names)) float64 in the given order."""
        index = {n: i for i, n in enumerate(self.names)}
        missing = [n for n in names if n not in index]
        if missing:
            raise KeyError(f"{self.dataset}: no feature(s) {missing[:5]} (has {len(self.names)} features)")
        return self.X[:, [index[n] for n in names]]

    def select(self, names: Sequence[str]) -> FeatureMatrix:
        return replace(self, X=self.columns(names), names=list(names))

    def without_shape(self, shape: str) -> FeatureMatrix:
        return self.rows(self.shapes != shape)

    def only_shape(self, shape: str) -> FeatureMatrix:
        return self.rows(self.shapes == shape)

    def __len__(self) -> int:
        return self.X.shape[0]


def clip_nonfinite(X: np.ndarray) -> np.ndarray:
    """+inf -> column's finite max, -inf -> finite min, NaN -> finite median (0 if none)."""
    X = np.array(X, dtype=np.float64)
    for j in range(X.shape[1]):
        col = X[:, j]
        fin = col[np.isfinite(col)]
        hi, lo, med = (fin.max(), fin.min(), float(np.median(fin))) if fin.size else (0.0, 0.0, 0.0)
        col[np.isposinf(col)] = hi
        col[np.isneginf(col)] = lo
        col[np.isnan(col)] = med
    return X


@dataclass(frozen=True)
class TargetScaling:
    """score -> [0, 1], oriented higher = more distorted: ``t = (s - lo) / (hi - lo)``, then
    ``1 - t`` when the published score grows with quality (``higher_is_better``)."""

    lo: float
    hi: float
    higher_is_better: bool = False
    name: str = "target"

    def forward(self, score: np.ndarray | float) -> np.ndarray | float:
        t = (np.asarray(score, dtype=np.float64) - self.lo) / (self.hi - self.lo)
        return 1.0 - t if self.higher_is_better else t

    def inverse(self, t: np.ndarray | float) -> np.ndarray | float:
        t = np.asarray(t, dtype=np.float64)
        t = 1.0 - t if self.higher_is_better else t
        return self.lo + t * (self.hi - self.lo)

    def to_dict(self) -> dict:
        return {"lo": float(self.lo), "hi": float(self.hi), "higher_is_better": bool(self.higher_is_better),
                "name": self.name}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> TargetScaling:
        return cls(float(d["lo"]), float(d["hi"]), bool(d.get("higher_is_better", False)), str(d.get("name", "target")))


def scale_targets(scores: Sequence[float], lo: float | None = None, hi: float | None = None,
                  higher_is_better: bool = False, name: str = "target") -> tuple[np.ndarray, TargetScaling]:
    """Scale one dataset's scores to [0, 1] (published range ``lo..hi``, else the data's min..max)."""
    s = np.asarray(scores, dtype=np.float64)
    lo = float(s.min()) if lo is None else float(lo)
    hi = float(s.max()) if hi is None else float(hi)
    if hi <= lo:
        hi = lo + 1.0
    scaling = TargetScaling(lo, hi, higher_is_better, name)
    return np.asarray(scaling.forward(s)), scaling


# --------------------------------------------------------------------------- correlations
def pearson(a: np.ndarray, b: np.ndarray) -> float:
    """Pearson r; 0.0 when either side is constant (no linear association measurable)."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    if a.size < 2:
        return 0.0
    a, b = a - a.mean(), b - b.mean()
    den = math.sqrt(float((a * a).sum()) * float((b * b).sum()))
    if den <= 1e-300 or not math.isfinite(den):
        return 0.0
    return float(np.clip((a * b).sum() / den, -1.0, 1.0))


def rankdata(a: np.ndarray) -> np.ndarray:
    """Average ranks (ties share the mean rank), like ``scipy.stats.rankdata``."""
    a = np.asarray(a, dtype=np.float64)
    order = np.argsort(a, kind="mergesort")
    ranks = np.empty(a.size, dtype=np.float64)
    sa = a[order]
    i = 0
    while i < a.size:
        j = i
        while j + 1 < a.size and sa[j + 1] == sa[i]:
            j += 1
        ranks[order[i:j + 1]] = 0.5 * (i + j) + 1.0
        i = j + 1
    return ranks


def spearman(a: np.ndarray, b: np.ndarray) -> float:
    """Spearman rho = Pearson of average ranks; 0.0 when either side is constant."""
    return pearson(rankdata(a), rankdata(b))


def per_shape_corr(pred: np.ndarray, target: np.ndarray, shapes: np.ndarray, kind: str = "pearson") -> dict[str, float]:
    fn = pearson if kind == "pearson" else spearman
    shapes = np.asarray(shapes).astype(str)
    return {s: fn(pred[shapes == s], target[shapes == s]) for s in dict.fromkeys(shapes.tolist())}


def mean_per_shape_corr(pred: np.ndarray, target: np.ndarray, shapes: np.ndarray, kind: str = "pearson") -> float:
    vals = list(per_shape_corr(pred, target, shapes, kind).values())
    return float(np.mean(vals)) if vals else 0.0


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


def minibatches(n: int, batch_size: int, rng: np.random.Generator) -> list[np.ndarray]:
    """A shuffled epoch of index batches; a last batch of one sample joins the previous one
    (batch norm needs two samples)."""
    perm = rng.permutation(n)
    batches = [perm[i:i + batch_size] for i in range(0, n, batch_size)]
    if len(batches) > 1 and len(batches[-1]) == 1:
        batches[-2] = np.concatenate([batches[-2], batches[-1]])
        batches.pop()
    return batches


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
    net = BatchedQualityMLP(m, d, seed=cfg.seed, **cfg.net_kwargs())
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
