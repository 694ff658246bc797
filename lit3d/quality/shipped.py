"""The quality model that ships with the package: a fitted fusion of :mod:`lit3d.quality.fusion`
(``AnchoredFusion`` or ``LinearFusion``) kept as JSON package data (``lit3d/quality/models/<name>.json``),
with its card.

The file holds ``{"name", "trained_on", "target": {"name", "lo", "hi", "higher_is_better"},
"feature_options": {...}, "fusion": <the model>.to_dict(), "cross_validated": {...}, "command"}``:
the feature options are those of :func:`lit3d.features.config.feature_config` (how the training
features were computed), the target says how the fusion's [0, 1] distortion maps back to the
opinion scale. ``lit3d-score`` and :func:`lit3d.score` use :data:`DEFAULT_MODEL` unless told
``--unlearned`` / given a checkpoint. Model card: ``docs/quality_model.md``.
"""
from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from lit3d.features.config import FeatureConfig, feature_config
from lit3d.features.matrix import TargetScaling
from lit3d.quality.fusion import AnchoredFusion, LinearFusion, fusion_from_dict
from lit3d.utils.errors import Lit3dError

MODELS_DIR = Path(__file__).resolve().parent / "models"
DEFAULT_MODEL = "cpcd2-phil-fusion"


class ShippedModelError(Lit3dError, ValueError):
    """A shipped model that cannot be read, or a feature table it cannot score."""


@dataclass
class ShippedQualityModel:
    """A loaded shipped model. ``predict`` maps one feature table to the opinion score."""

    name: str
    fusion: LinearFusion | AnchoredFusion
    scaling: TargetScaling
    trained_on: str
    feature_options: dict
    card: dict

    @property
    def features(self) -> list[str]:
        return self.fusion.inputs

    def feature_config(self) -> FeatureConfig:
        """The configuration the training features were computed with."""
        return feature_config(self.feature_options)

    def missing(self, features: Mapping[str, float]) -> list[str]:
        """The model's features that ``features`` lacks or holds as non-finite values."""
        return [f for f in self.fusion.inputs if not math.isfinite(float(features.get(f, math.nan)))]

    def predict(self, features: Mapping[str, float]) -> dict:
        """``{"score": opinion score, "distortion": [0, 1] model output (higher = worse), "model", "trained_on",
        "description", "features"}`` of one feature table (``name -> float``, extra names ignored).
        Raises :class:`ShippedModelError` when a feature is missing (e.g. a mesh pair: no point colours)."""
        missing = self.missing(features)
        if missing:
            raise ShippedModelError(f"the shipped quality model '{self.name}' needs {len(missing)} feature(s) this "
                                    f"table lacks, e.g. {missing[:3]} (it scores coloured point-cloud pairs)")
        x = np.array([[float(features[f]) for f in self.fusion.inputs]])
        distortion = float(np.clip(1.0 - self.fusion.quality(x)[0], 0.0, 1.0))
        s = self.scaling
        better = "higher = better" if s.higher_is_better else "higher = more distorted"
        return {"score": float(s.inverse(distortion)), "distortion": distortion, "model": self.name,
                "trained_on": self.trained_on, "features": self.features,
                "description": f"{s.name} {s.lo:g}..{s.hi:g}, {better}; trained on {self.trained_on}"}


def model_document(name: str, trained_on: str, scaling: TargetScaling, feature_options: Mapping, chosen,
                   cross_validated: Mapping, command: str) -> dict:
    """The JSON document of a quality model (this module's format) from a fitted
    :class:`lit3d.quality.fusion.ChosenFusion` ``chosen``; ``cross_validated``: ``{row: {metric: value or
    (value, lo, hi)}}`` (intervals rounded to 4 digits)."""
    cv = {row: {k: [round(float(x), 4) for x in v] if isinstance(v, (tuple, list)) else v for k, v in m.items()}
          for row, m in cross_validated.items()}
    return {"name": name, "trained_on": trained_on,
            "target": {"name": scaling.name, "lo": scaling.lo, "hi": scaling.hi,
                       "higher_is_better": scaling.higher_is_better},
            "feature_options": dict(feature_options), "fusion": chosen.model.to_dict(), "chosen": chosen.chosen,
            "described": chosen.model.describe(),
            "inner_scores": {k: round(v, 4) for k, v in chosen.scores.items()},
            "cross_validated": cv, "command": command}


def model_names() -> list[str]:
    """Names of the shipped quality models."""
    return sorted(p.stem for p in MODELS_DIR.glob("*.json"))


def load_shipped(name: str = DEFAULT_MODEL) -> ShippedQualityModel:
    """Read the shipped model ``name`` (:func:`model_names`)."""
    path = MODELS_DIR / f"{name}.json"
    if not path.is_file():
        raise ShippedModelError(f"no shipped quality model '{name}' (have: {', '.join(model_names()) or 'none'})")
    return _load(str(path))


def load_model_file(path: str | Path) -> ShippedQualityModel:
    """Read a quality model written in this module's format (e.g. ``quality_model.json`` of a
    ``lit3d-train experiment=quality_cpcd2_fusion`` run)."""
    path = Path(path).expanduser().resolve()
    if not path.is_file():
        raise ShippedModelError(f"{path}: no such quality model file")
    return _load(str(path))


@lru_cache(maxsize=4)
def _load(path: str) -> ShippedQualityModel:
    try:
        d = json.loads(Path(path).read_text())
        t = d["target"]
        scaling = TargetScaling(float(t["lo"]), float(t["hi"]), bool(t["higher_is_better"]), str(t["name"]))
        return ShippedQualityModel(d["name"], fusion_from_dict(d["fusion"]), scaling, d["trained_on"],
                                   dict(d.get("feature_options") or {}), d)
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise ShippedModelError(f"{path}: not a readable shipped quality model ({exc})") from exc
