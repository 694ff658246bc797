"""The completion DataModule's settings as frozen dataclasses, one per config node of ``data``
(:class:`~datamodules.completion.datamodule.CompletionDataModule`):

    data.categories  the seen and unseen categories (:class:`CategorySettings`)
    data.render      how the 2.5D views are made: views, image size, sensor (:class:`RenderSettings`)
    data.recgan      the 3D-RecGAN++ release's own settings (:class:`RecganSettings`)
    data.meshes      the mesh sources' own settings (:class:`MeshSettings`)
    data.prepare     how the cache is written (:class:`PrepareSettings`)

:func:`parse` turns a node (a mapping, None for the defaults, or the dataclass itself) into its dataclass; an
unknown key is a :class:`~datamodules.completion.plan.DataConfigError` naming ``data.<node>.<key>``. Configs
written before these nodes hold the keys flat: :mod:`datamodules.completion.flat_config` moves them.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from datamodules.completion.plan import DataConfigError
from lit3d.utils.settings_nodes import parse_node

DEFAULT_MODEL_SPLIT = {"train": 0.7, "val": 0.1, "test": 0.2}


def _tuple(x) -> tuple | None:
    return None if x is None else tuple(x)


@dataclass(frozen=True)
class CategorySettings:
    """``seen``: the categories of train/val/test_same/test_cross (None: every seen category of
    :mod:`lit3d.utils.shapenet_categories`; ``source=meshes``: every category folder of ``root`` but the unseen
    ones); ``unseen``: those of test_unseen / test_unseen_cross (None: every unseen category)."""

    seen: Sequence[str] | None = None
    unseen: Sequence[str] | None = None

    def __post_init__(self):
        object.__setattr__(self, "seen", _tuple(self.seen))
        object.__setattr__(self, "unseen", _tuple(self.unseen))


@dataclass(frozen=True)
class RenderSettings:
    """``views_per_shape`` views of each shape instance (synthetic and mesh sources), test_unseen from the
    ``unseen_view_set`` (``same`` or ``cross``), depth images of ``render_factor`` x target_res pixels through
    ``sensor`` (:mod:`lit3d.sensing.sensor`: ``ortho``, ``recgan`` or a dict of Sensor fields)."""

    views_per_shape: int = 4
    unseen_view_set: str = "same"
    render_factor: int = 2
    sensor: str | Mapping = "ortho"

    def __post_init__(self):
        if isinstance(self.sensor, Mapping):
            object.__setattr__(self, "sensor", dict(self.sensor))


@dataclass(frozen=True)
class RecganSettings:
    """``val_fraction``: the share of the release's training shape ids held out for validation; ``raw_res``: its
    grids centre-padded or cropped to raw_res^3 (None: the release's 256)."""

    val_fraction: float = 0.1
    raw_res: int | None = None


@dataclass(frozen=True)
class MeshSettings:
    """Models per category split by ``model_split`` (shares of train, val, test; None: 0.7/0.1/0.2), categories
    with fewer than ``min_models`` models noted, ``up_axis`` the models' up axis; ``procedural_share``: that share
    of the training items made from procedural shapes instead (validation and test stay real)."""

    model_split: Mapping[str, float] | None = None
    min_models: int = 8
    up_axis: str = "y"
    procedural_share: float = 0.0

    def __post_init__(self):
        shares = {str(k): float(v) for k, v in dict(self.model_split or DEFAULT_MODEL_SPLIT).items()}
        if set(shares) != set(DEFAULT_MODEL_SPLIT) or min(shares.values()) < 0:
            raise DataConfigError(f"data.meshes.model_split={shares}: expected fractions >= 0 for train, val and test")
        object.__setattr__(self, "model_split", shares)
        if not 0.0 <= float(self.procedural_share) <= 1.0:
            raise DataConfigError(f"data.meshes.procedural_share={self.procedural_share}: expected a share in [0, 1]")


@dataclass(frozen=True)
class PrepareSettings:
    """Preparation in ``workers`` processes (0: in this one) with a ``progress`` bar; ``skip_bad``: unreadable
    files or models skipped with a warning (counted) instead of raising; ``compress``: zlib on the packed bits."""

    workers: int = 0
    progress: bool = True
    skip_bad: bool = False
    compress: bool = True


def parse(cls, node, name: str):
    """``node`` (a mapping, None for the defaults, or already a ``cls``) as a ``cls``; DataConfigError naming
    ``data.<name>.<key>`` for a key ``cls`` does not have (:func:`lit3d.utils.settings_nodes.parse_node`)."""
    return parse_node(cls, node, f"data.{name}", DataConfigError)
