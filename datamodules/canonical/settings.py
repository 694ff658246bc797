"""The canonical DataModule's settings as frozen dataclasses, one per config node.

    data.source    one node per data source (``kind`` names it), only that source's fields:
                   :class:`SynthSettings`, :class:`AnnySettings`, :class:`ToscaSettings`,
                   :class:`Shrec14Settings`, :class:`FaustSettings`, :class:`SumnerSettings`
    data.render    what the cached images are rendered with (:class:`RenderSettings`)
    data.split.mode     which items train, validate and test (:class:`SplitSettings`)
    data.training  what only training items get (:class:`TrainingSettings`)

:func:`parse` turns a node (a mapping, or the dataclass itself) into its dataclass; an unknown key is a
:class:`~datamodules.cache.DataError` naming it and the node's fields. Sequences become tuples, so
every settings object is hashable (a worker process caches its renderer by them).
"""
from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from typing import ClassVar

from datamodules.cache import DataError
from datamodules.canonical.parked import PARKED_DATA, PARKED_TAG
from lit3d.geometry.broadside import VIEW_MODES
from lit3d.utils.settings_nodes import parse_node

SCALE_MODES = ("shape", "subject")
SPLIT_MODES = ("subject_pose", "pose", "all")
VAL_POSES = ("training", "own")  # split.val_poses: which poses the validation subjects are seen in
POSE_DRAWS = ("shared", "per_subject")  # synth, Anny: pose p the same for every subject, or each subject's own


def _tuple(x) -> tuple | None:
    return None if x is None else tuple(x)


@dataclass(frozen=True)
class SynthSettings:
    """Procedural figures (``kinds`` in turn): ``n_subjects`` figures drawn with ``seed`` x ``n_poses`` poses
    drawn with ``pose_seed`` (turned by up to ``yaw_range`` degrees, joint angles x ``pose_strength``),
    meshed at ``mesh_resolution``; ``pose_draw``: :data:`POSE_DRAWS`; ``own_poses`` = N: every figure N more
    training-only poses of its own."""

    kind: ClassVar[str] = "synth"
    kinds: tuple[str, ...] = ("humanoid", "quadruped")
    n_subjects: int = 12
    n_poses: int = 12
    mesh_resolution: int = 56
    seed: int = 42
    pose_seed: int = 0
    yaw_range: float = 15.0
    pose_strength: float = 1.0
    pose_draw: str = "shared"
    own_poses: int = 0

    def __post_init__(self):
        object.__setattr__(self, "kinds", _tuple(self.kinds))
        if self.pose_draw not in POSE_DRAWS:
            raise DataError(f"unknown pose_draw '{self.pose_draw}' ({', '.join(POSE_DRAWS)}; data.source.pose_draw)")

    def cache_fields(self, root: str | None) -> dict:
        """The fields that change the cached images, under the keys the caches have always hashed."""
        out = {k: getattr(self, k) for k in ("kinds", "n_subjects", "n_poses", "mesh_resolution", "pose_seed",
                                             "yaw_range", "pose_strength", "seed")}
        out["kinds"] = list(self.kinds)
        if self.pose_draw != "shared":  # absent for the old draw: its caches keep their hash
            out["pose_draw"] = self.pose_draw
        if self.own_poses:
            out["own_poses"] = int(self.own_poses)
        return out


@dataclass(frozen=True)
class AnnySettings:
    """People from the Anny body model: ``n_subjects`` phenotypes drawn with ``body_seed`` (``phenotypes``:
    ``uniform`` or ``adult``) x ``n_poses`` joint-limit poses drawn with ``pose_seed``."""

    kind: ClassVar[str] = "anny"
    n_subjects: int = 12
    n_poses: int = 12
    body_seed: int = 0
    pose_seed: int = 0
    yaw_range: float = 15.0
    pose_strength: float = 1.0
    phenotypes: str = "uniform"
    pose_draw: str = "shared"

    def __post_init__(self):
        if self.pose_draw not in POSE_DRAWS:
            raise DataError(f"unknown pose_draw '{self.pose_draw}' ({', '.join(POSE_DRAWS)}; data.source.pose_draw)")

    def cache_fields(self, root: str | None) -> dict:
        out = {k: getattr(self, k) for k in ("n_subjects", "n_poses", "body_seed", "pose_seed", "yaw_range",
                                             "pose_strength")}
        if self.phenotypes != "uniform":  # absent for the old draw: its caches keep their hash
            out["phenotypes"] = self.phenotypes
        if self.pose_draw != "shared":
            out["pose_draw"] = self.pose_draw
        return out


def _mesh_fields(root, classes=None, canonical_pose=0, up_axis="z", cla=None) -> dict:
    """The cached-image fields of a mesh-file source, with the values the caches of one flat config held
    for the fields a source does not have (their hashes stay)."""
    return {"root": root, "classes": None if classes is None else list(classes), "canonical_pose": canonical_pose,
            "up_axis": up_axis, "cla": cla}


@dataclass(frozen=True)
class ToscaSettings:
    """TOSCA meshes under ``data.root``: ``classes`` (None: every class found), canonical = pose
    ``canonical_pose``; ``up_axis`` "z" meshes are turned to y up."""

    kind: ClassVar[str] = "tosca"
    classes: tuple[str, ...] | None = None
    canonical_pose: int = 0
    up_axis: str = "z"

    def __post_init__(self):
        object.__setattr__(self, "classes", _tuple(self.classes))

    def cache_fields(self, root: str | None) -> dict:
        return _mesh_fields(root, self.classes, self.canonical_pose, self.up_axis)


@dataclass(frozen=True)
class Shrec14Settings:
    """SHREC'14 humans under ``data.root`` with a PSB ``cla`` (None: the one found under the root);
    canonical = pose ``canonical_pose`` of each class."""

    kind: ClassVar[str] = "shrec14"
    cla: str | None = None
    canonical_pose: int = 0
    up_axis: str = "z"

    def cache_fields(self, root: str | None) -> dict:
        return _mesh_fields(root, None, self.canonical_pose, self.up_axis, self.cla)


@dataclass(frozen=True)
class FaustSettings:
    """FAUST registrations under ``data.root``; canonical = pose ``canonical_pose`` (also an item)."""

    kind: ClassVar[str] = "faust"
    canonical_pose: int = 0

    def cache_fields(self, root: str | None) -> dict:
        return _mesh_fields(root, None, self.canonical_pose)


@dataclass(frozen=True)
class SumnerSettings:
    """Sumner & Popovic's animals under ``data.root`` (``classes``: None = every animal found)."""

    kind: ClassVar[str] = "sumner"
    classes: tuple[str, ...] | None = None

    def __post_init__(self):
        object.__setattr__(self, "classes", _tuple(self.classes))

    def cache_fields(self, root: str | None) -> dict:
        return _mesh_fields(root, self.classes)


SOURCE_SETTINGS = {c.kind: c for c in (SynthSettings, ToscaSettings, Shrec14Settings, AnnySettings, FaustSettings,
                                       SumnerSettings)}
CANONICAL_SOURCES = tuple(SOURCE_SETTINGS)
ROOTLESS = ("synth", "anny")  # sources that need no root folder
SourceSettings = SynthSettings | AnnySettings | ToscaSettings | Shrec14Settings | FaustSettings | SumnerSettings


@dataclass(frozen=True)
class RenderSettings:
    """What the cached images are rendered with: every shape turned by ``view_mode``'s azimuth plus each of
    ``azimuths`` (degrees), scaled by ``scale_mode`` (:data:`SCALE_MODES`); ``flow_targets``: also the warp
    head's backward flow and visibility."""

    azimuths: tuple[float, ...] = (0.0,)
    view_mode: str = "fixed"
    scale_mode: str = "shape"
    flow_targets: bool = False

    def __post_init__(self):
        object.__setattr__(self, "azimuths", _tuple(self.azimuths))
        _choice("render.scale_mode", self.scale_mode, SCALE_MODES)
        _choice("render.view_mode", self.view_mode, VIEW_MODES)


@dataclass(frozen=True)
class SplitSettings:
    """Which items train, validate and test (:mod:`datamodules.canonical.splits`): ``mode``
    (:data:`SPLIT_MODES`) dealt with ``seed`` (None: the DataModule's seed) into ``n_folds`` folds, fold
    ``fold`` tested; validation: ``val_subjects`` subjects of their own (None: the old mixed rule) seen in
    ``val_poses``, ``val_per_subject`` poses per subject (``mode=pose``), at most ``max_val_items``;
    ``train_pose_fraction`` of each subject's training poses; ``eval_views``: the views val and test use
    (None: every one)."""

    mode: str = "subject_pose"
    seed: int | None = None
    n_folds: int = 3
    fold: int = 0
    val_per_subject: int = 1
    max_val_items: int | None = 64
    val_subjects: int | None = None
    val_poses: str = "training"
    train_pose_fraction: float = 1.0
    eval_views: tuple[int, ...] | None = None

    def __post_init__(self):
        object.__setattr__(self, "eval_views", _tuple(self.eval_views))
        _choice("split.mode", self.mode, SPLIT_MODES)
        _choice("split.val_poses", self.val_poses, VAL_POSES)


@dataclass(frozen=True)
class TrainingSettings:
    """What only the training items get: ``flip_lr`` (mirrored left-right, p = 1/2), ``roll_deg`` (turned in
    the image plane by up to that), ``blend_poses`` extra blended poses per subject; batches drawn with every
    subject equally often (``balance_subjects``)."""

    flip_lr: bool = False
    roll_deg: float = 0.0
    blend_poses: int = 0
    balance_subjects: bool = False


def _choice(name: str, value, choices: Sequence[str]) -> None:
    """DataError unless ``value`` is one of ``choices`` (``name``: the key under ``data.``)."""
    if value not in choices:
        raise DataError(f"data.{name} must be one of {', '.join(choices)}, got '{value}'")


def parse(cls, node, name: str):
    """``node`` (a mapping, None for the defaults, or already a ``cls``) as a ``cls``; DataError naming
    ``data.<name>.<key>`` for a key ``cls`` does not have (:func:`lit3d.utils.settings_nodes.parse_node`), and
    where the code of a removed option is for one of :data:`datamodules.canonical.parked.PARKED_DATA`."""
    removed = [] if isinstance(node, cls) else [k for k in (node or {}) if f"{name}.{k}" in PARKED_DATA]
    if removed:
        raise DataError(f"data.{name}.{removed[0]}: removed (an option measured and not adopted); its code is at "
                        f"git tag {PARKED_TAG}")
    return parse_node(cls, node, f"data.{name}", DataError)


def parse_source(node) -> SourceSettings:
    """The ``data.source`` node (``{"kind": ..., **fields}``, or already settings) as its source's settings."""
    if isinstance(node, tuple(SOURCE_SETTINGS.values())):
        return node
    node = dict(node or {})
    kind = node.pop("kind", None)
    if kind not in SOURCE_SETTINGS:
        raise DataError(f"unknown canonical data source '{kind}' ({', '.join(CANONICAL_SOURCES)}; data.source.kind)")
    return parse(SOURCE_SETTINGS[kind], node, f"source ({kind})")


def as_node(settings) -> dict:
    """Settings as a plain config node (tuples as lists; a source with its ``kind`` first)."""
    out = {"kind": settings.kind} if isinstance(settings, tuple(SOURCE_SETTINGS.values())) else {}
    for f in dataclasses.fields(settings):
        v = getattr(settings, f.name)
        out[f.name] = list(v) if isinstance(v, tuple) else v
    return out
