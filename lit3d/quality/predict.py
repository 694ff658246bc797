"""Use a trained quality checkpoint on one feature table (for ``lit3d-score --ckpt``).

The checkpoint of :class:`lit3d.tasks.quality.QualityTask` stores, as plain values,
``checkpoint["quality"] = {"features": [...selected names...], "net": {...},
"scaling": {"lo", "hi", "higher_is_better", "name"}, "sfs": ..., "dataset": ...,
"feature_options": {size, styles, measures, ...}}`` (how the training features were rendered).
Loading uses ``torch.load(weights_only=True)`` and needs no Lightning and no data.

    from lit3d.quality.predict import predict_from_features, load_predictor
    score = predict_from_features("best.ckpt", features)   # features: name -> float
    p = load_predictor("best.ckpt"); p.features; p.predict(features)  # -> dict with details
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import torch

from lit3d.nets.quality import QualityMLP
from lit3d.quality.protocol import TargetScaling

CKPT_KEY = "quality"


class QualityCheckpointError(ValueError):
    """The file is not a usable quality checkpoint, or the features do not fit it."""


@dataclass
class QualityPredictor:
    """A loaded quality model: selected feature names -> score."""

    features: list[str]
    net: QualityMLP
    scaling: TargetScaling | None
    dataset: str | None = None
    path: str = ""
    # the data's feature options (render size, styles, measures, ...): render new pairs the same way,
    # e.g. ``datamodules.quality.feature_config(predictor.feature_options)``
    feature_options: dict | None = None

    @property
    def target_name(self) -> str:
        return self.scaling.name if self.scaling else "distortion"

    def predict(self, features: Mapping[str, float]) -> dict:
        """``{"score": on the training dataset's scale, "distortion": model output in [0, 1]
        (higher = more distorted), "target": what the score is, "features": used names}``."""
        missing = [f for f in self.features if f not in features]
        if missing:
            raise QualityCheckpointError(
                f"{self.path}: the feature table lacks {len(missing)} of the {len(self.features)} features this "
                f"model uses, e.g. {missing[:3]} (render with the styles/shadings/measures it was trained on)")
        values = [float(features[f]) for f in self.features]
        bad = [f for f, v in zip(self.features, values) if not math.isfinite(v)]
        if bad:
            raise QualityCheckpointError(f"{self.path}: non-finite feature value(s) for {bad[:3]}")
        with torch.no_grad():
            out = float(self.net(torch.tensor([values], dtype=torch.float32))[0])
        score = float(self.scaling.inverse(out)) if self.scaling else out
        return {"score": score, "distortion": out, "target": self.target_name, "features": list(self.features),
                "dataset": self.dataset}


def load_predictor(ckpt_path: str | Path) -> QualityPredictor:
    """Read a quality checkpoint (``weights_only=True``) into a :class:`QualityPredictor`."""
    path = Path(ckpt_path)
    return _load(str(path.resolve()), path.stat().st_mtime_ns if path.is_file() else 0)


@lru_cache(maxsize=4)
def _load(path: str, _mtime: int) -> QualityPredictor:
    p = Path(path)
    if not p.is_file():
        raise QualityCheckpointError(f"{p}: checkpoint not found")
    try:
        ckpt = torch.load(p, map_location="cpu", weights_only=True)
    except Exception as exc:
        raise QualityCheckpointError(f"{p}: not a readable checkpoint ({type(exc).__name__}: {exc})") from exc
    meta = ckpt.get(CKPT_KEY) if isinstance(ckpt, dict) else None
    if not isinstance(meta, dict) or not meta.get("features"):
        raise QualityCheckpointError(f"{p}: not a quality checkpoint (no '{CKPT_KEY}' entry with selected features)")
    net = QualityMLP(len(meta["features"]), **dict(meta.get("net") or {}))
    state = {k[len("net."):]: v for k, v in ckpt.get("state_dict", {}).items() if k.startswith("net.")}
    try:
        net.load_state_dict(state)
    except RuntimeError as exc:
        raise QualityCheckpointError(f"{p}: weights do not match the stored network ({exc})") from exc
    scaling = TargetScaling.from_dict(meta["scaling"]) if meta.get("scaling") else None
    return QualityPredictor(list(meta["features"]), net.eval(), scaling, meta.get("dataset"), str(p),
                            meta.get("feature_options"))


def predict_from_features(ckpt_path: str | Path, features: Mapping[str, float]) -> float:
    """Predicted score of one mesh pair on the training dataset's scale and direction
    (e.g. MOS 0-10 for LIRIS/EPFL; ordinal severity in [0, 1] for the synthetic set)."""
    return float(load_predictor(ckpt_path).predict(features)["score"])


def required_features(ckpt_path: str | Path) -> list[str]:
    """The feature names a checkpoint needs (so a caller renders only those styles)."""
    return list(load_predictor(ckpt_path).features)
