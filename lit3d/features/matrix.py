"""A dataset of shape pairs as a feature matrix (``FeatureMatrix``), the scaling of its
opinion scores to [0, 1] (``TargetScaling``) and the shuffled minibatches its rows are trained
in (``minibatches``: the one batching rule of the quality MLP, used by the Lightning data loader
and by ``lit3d.quality.trainer`` alike). Plain NumPy: no rendering, no nets."""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np


# --------------------------------------------------------------------------- batching
def minibatches(n: int, batch_size: int, rng: np.random.Generator) -> list[np.ndarray]:
    """One shuffled epoch of row-index batches (each (b,) int64) of ``n`` rows.

    ``rng.permutation(n)`` cut into ``batch_size`` pieces; a last batch of one row joins the
    previous one (batch norm needs two samples). Successive calls with one ``rng`` give the
    successive epochs.
    """
    perm = rng.permutation(n)
    batches = [perm[i:i + batch_size] for i in range(0, n, batch_size)]
    if len(batches) > 1 and len(batches[-1]) == 1:
        batches[-2] = np.concatenate([batches[-2], batches[-1]])
        batches.pop()
    return batches


def minibatch_count(n: int, batch_size: int) -> int:
    """``len(minibatches(n, batch_size, rng))`` without drawing."""
    count = -(-n // batch_size)
    return count - 1 if count > 1 and n % batch_size == 1 else count


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


