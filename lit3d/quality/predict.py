"""Use a trained quality checkpoint on one feature table (for ``lit3d-score --ckpt``).

The checkpoint of :class:`lit3d.quality.module.QualityTask` stores, as plain values,
``checkpoint["quality"] = {"features": [...selected names, in input order...], "net": {...},
"scaling": {"lo", "hi", "higher_is_better", "name"}, "sfs": ..., "dataset": ...,
"feature_options": {size, styles, measures, ...}}`` (how the training features were rendered),
and ``lit3d-train`` adds ``checkpoint["lit3d"] = {"task": task config, "data": data config, ...}``
(:class:`lit3d.callbacks.metadata.MetadataCallback`). Loading uses
``torch.load(weights_only=True)`` and needs no Lightning and no data.

    from lit3d.quality.predict import predict_from_features, load_predictor
    score = predict_from_features("best.ckpt", features)   # features: name -> float
    p = load_predictor("best.ckpt")
    cfg = p.feature_config()                 # render a new pair exactly as the training pairs
    p.predict(feature_table(ref, dist, cfg).features)   # -> dict with score and details
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import torch

from lit3d.features.config import FeatureConfig, feature_config
from lit3d.quality.checkpoint_upgrade import upgrade_checkpoint
from lit3d.quality.nets import QualityMLP
from lit3d.quality.protocol import TargetScaling
from lit3d.utils.checkpoints import META_KEY, first_line, load_checkpoint
from lit3d.utils.errors import Lit3dError

CKPT_KEY = "quality"
QUALITY_TARGET = "lit3d.quality.module.QualityTask"


class QualityCheckpointError(Lit3dError, ValueError):
    """The file is not a usable quality checkpoint, or the features do not fit it."""


@dataclass
class QualityPredictor:
    """A loaded quality model: selected feature names -> score.

    Attributes:
        features: the F selected feature names, in the network's input order.
        net: the thesis MLP in eval mode, ``(B, F) float32 -> (B,)`` distortion in (0, 1).
        scaling: maps the [0, 1] output back to the training dataset's score (None: report it as is).
        dataset: training dataset name (``synth``, ``liris_epfl``, ...).
        path: the checkpoint path as given.
        feature_options: the data's feature options (render size, styles, measures, ...) used to
            compute the training features; None when the checkpoint does not record them.
        feature_fn: the data's custom feature function (``data.feature_tables.fn``), None = the renderer's
            feature table (:func:`lit3d.features.table.feature_table`).
    """

    features: list[str]
    net: QualityMLP
    scaling: TargetScaling | None
    dataset: str | None = None
    path: str = ""
    feature_options: dict | None = None
    feature_fn: str | None = None

    @property
    def target_name(self) -> str:
        return self.scaling.name if self.scaling else "distortion"

    def feature_config(self) -> FeatureConfig:
        """:func:`lit3d.features.config.feature_config` of :attr:`feature_options`: the
        configuration the training features were computed with."""
        return feature_config(self.feature_options)

    def describe_target(self) -> str:
        """One line: what :meth:`predict`'s ``score`` is, its range and direction."""
        if self.scaling is None:
            return "model output in [0, 1], higher = more distorted"
        s = self.scaling
        better = "higher = better" if s.higher_is_better else "higher = more distorted"
        return f"{s.name} of the '{self.dataset or '?'}' data, range {s.lo:g}..{s.hi:g}, {better}"

    def predict(self, features: Mapping[str, float]) -> dict:
        """One pair's score from its feature table (``name -> float``; extra names are ignored).

        Returns ``{"score": on the training dataset's scale and direction, "distortion": model
        output in [0, 1] (higher = more distorted), "target": what the score is, "score_range":
        [lo, hi], "higher_is_better": bool, "description": :meth:`describe_target`, "features":
        used names, "dataset": training dataset}``. Raises :class:`QualityCheckpointError` when a
        selected feature is missing or not finite.
        """
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
            out = float(self.net(torch.tensor([values], dtype=torch.float32))[0])  # (1, F) -> (1,)
        sc = self.scaling
        return {"score": float(sc.inverse(out)) if sc else out, "distortion": out, "target": self.target_name,
                "score_range": [sc.lo, sc.hi] if sc else [0.0, 1.0],
                "higher_is_better": bool(sc.higher_is_better) if sc else False,
                "description": self.describe_target(), "features": list(self.features), "dataset": self.dataset}


def load_predictor(ckpt_path: str | Path) -> QualityPredictor:
    """Read a quality checkpoint (``weights_only=True``) into a :class:`QualityPredictor`.

    Raises :class:`QualityCheckpointError` (one line, naming the file) for a missing or unreadable
    file, a checkpoint of another lit3d task (``PATH: checkpoint is a <task> model, expected a
    quality model``), or one without the quality entry.
    """
    path = Path(ckpt_path)
    return _load(str(path), str(path.resolve()), path.stat().st_mtime_ns if path.is_file() else 0)


def _is_quality(task_cfg: Mapping) -> bool:
    target = task_cfg.get("_target_")
    return target == QUALITY_TARGET if target else task_cfg.get("name") == "quality"


def _task_name(task_cfg: Mapping) -> str:
    return str(task_cfg.get("name") or str(task_cfg.get("_target_", "unknown")).rsplit(".", 1)[-1])


@lru_cache(maxsize=4)
def _load(path: str, _resolved: str, _mtime: int) -> QualityPredictor:
    p = Path(path)
    ckpt = upgrade_checkpoint(load_checkpoint(p, QualityCheckpointError))  # its data config in today's layout
    lit3d = ckpt.get(META_KEY) if isinstance(ckpt, dict) else None
    task_cfg = lit3d.get("task") if isinstance(lit3d, dict) else None
    if isinstance(task_cfg, Mapping) and not _is_quality(task_cfg):
        raise QualityCheckpointError(f"{p}: checkpoint is a {_task_name(task_cfg)} model, expected a quality model")
    meta = ckpt.get(CKPT_KEY) if isinstance(ckpt, dict) else None
    if not isinstance(meta, dict) or not meta.get("features"):
        raise QualityCheckpointError(f"{p}: not a lit3d quality checkpoint (no '{CKPT_KEY}' entry with selected "
                                     "features; train one with lit3d-train task=quality)")
    if not isinstance(meta.get("net"), dict) or not {"hidden", "blocks"} <= set(meta["net"]):
        raise QualityCheckpointError(f"{p}: the quality checkpoint does not say its MLP's sizes ('{CKPT_KEY}.net' "
                                     "with hidden and blocks)")
    net = QualityMLP(len(meta["features"]), **dict(meta["net"]))
    state = {k[len("net."):]: v for k, v in ckpt.get("state_dict", {}).items() if k.startswith("net.")}
    try:
        net.load_state_dict(state)
    except RuntimeError as exc:
        raise QualityCheckpointError(f"{p}: weights do not match the stored network ({first_line(exc)})") from exc
    scaling = TargetScaling.from_dict(meta["scaling"]) if meta.get("scaling") else None
    data_cfg = lit3d.get("data") if isinstance(lit3d, dict) and isinstance(lit3d.get("data"), Mapping) else {}
    features = data_cfg.get("feature_tables") or {}
    options = meta.get("feature_options")
    if options is None:
        options = features.get("options")
    return QualityPredictor(list(meta["features"]), net.eval(), scaling, meta.get("dataset"), str(p),
                            None if options is None else dict(options), features.get("fn"))


def predict_from_features(ckpt_path: str | Path, features: Mapping[str, float]) -> float:
    """Predicted score of one mesh pair on the training dataset's scale and direction
    (e.g. MOS 0-10 for LIRIS/EPFL; ordinal severity in [0, 1] for the synthetic set)."""
    return float(load_predictor(ckpt_path).predict(features)["score"])


def required_features(ckpt_path: str | Path) -> list[str]:
    """The feature names a checkpoint needs (so a caller renders only those styles)."""
    return list(load_predictor(ckpt_path).features)
