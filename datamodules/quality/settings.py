"""The quality DataModule's settings as frozen dataclasses, one per config node of ``data``
(:class:`~datamodules.quality.datamodule.QualityDataModule`):

    data.synth     the synthetic set: reference shapes, distortions and their levels (:class:`SynthSettings`)
    data.feature_tables  how the feature tables are computed (:class:`FeatureSettings`)
    data.split     which groups are held out (:class:`SplitSettings`)

:func:`parse` turns a node (a mapping, None for the defaults, or the dataclass itself) into its dataclass; an
unknown key is a :class:`~datamodules.cache.DataError` naming ``data.<node>.<key>``. Configs written before
these nodes hold the keys flat: :mod:`datamodules.quality.flat_config` moves them.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from datamodules.cache import DataError
from datamodules.quality.distortions import DISTORTIONS
from datamodules.quality.quality_shapes import PROCEDURAL_SHAPES
from lit3d.utils.settings_nodes import parse_node

GROUPS = ("shape", "family")


@dataclass(frozen=True)
class SynthSettings:
    """The procedural reference ``shapes`` (meshed with ``subdivisions``) plus every mesh of ``user_mesh_dir``, each
    distorted by ``distortions`` at ``levels`` (None: :data:`datamodules.quality.distortions.LEVELS`), keeping
    ``n_levels`` of each spread from mildest to strongest (None: all)."""

    shapes: Sequence[str] = PROCEDURAL_SHAPES
    user_mesh_dir: str | None = None
    distortions: Sequence[str] = DISTORTIONS
    levels: Mapping[str, Sequence[float]] | None = None
    n_levels: int | None = None
    subdivisions: int = 4

    def __post_init__(self):
        object.__setattr__(self, "shapes", tuple(self.shapes))
        object.__setattr__(self, "distortions", tuple(self.distortions))


@dataclass(frozen=True)
class FeatureSettings:
    """Feature tables from ``fn`` (a custom feature function, ``module:function``; None: the renderer's), with
    ``options`` (:class:`lit3d.features.table.FeatureConfig` fields: size, styles, measures, ...), computed in
    ``workers`` processes (0: in this one)."""

    fn: str | None = None
    options: Mapping[str, Any] = field(default_factory=dict)
    workers: int = 0

    def __post_init__(self):
        object.__setattr__(self, "options", dict(self.options or {}))


@dataclass(frozen=True)
class SplitSettings:
    """``test_shapes`` / ``val_shapes`` are held out, the rest trains (``[]``: none held out; None: the last group,
    and for validation the one before it); the groups are the reference shapes (``groups=shape``) or the
    distortion families of CPCD2-style stimulus names (``family``)."""

    test_shapes: Sequence[str] | None = None
    val_shapes: Sequence[str] | None = None
    groups: str = "shape"

    def __post_init__(self):
        for name in ("test_shapes", "val_shapes"):
            value = getattr(self, name)
            object.__setattr__(self, name, None if value is None else tuple(value))
        if self.groups not in GROUPS:
            raise DataError(f"data.split.groups must be 'shape' or 'family', got {self.groups!r}")


def parse(cls, node, name: str):
    """``node`` (a mapping, None for the defaults, or already a ``cls``) as a ``cls``; DataError naming
    ``data.<name>.<key>`` for a key ``cls`` does not have (:func:`lit3d.utils.settings_nodes.parse_node`)."""
    return parse_node(cls, node, f"data.{name}", DataError)
