"""The canonical task's settings as frozen dataclasses, one per config node of ``task``.

    task.optimizer    Adam and its rate's schedule (:class:`OptimizerSettings`)
    task.phases       the depth and mask weights alpha/beta over the run (:class:`PhaseSettings`)
    task.warp         the warp head's terms (:class:`WarpObjective`)
    task.identity     a subject classifier on the MSFE latent (:class:`IdentityObjective`)
    task.panels       validation image panels (:class:`PanelSettings`)

An objective with ``weight`` 0 is off. :func:`parse` turns a node (a mapping, None for the defaults, or the
dataclass itself) into its dataclass; an unknown key is a ValueError naming ``task.<node>.<key>``.
Sequences become tuples, so the settings are hashable and compare by value.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from lit3d.utils.settings_nodes import parse_node

LR_SCHEDULES = ("constant", "cosine")  # task.optimizer.schedule


def _tuple(x) -> tuple | None:
    return None if x is None else tuple(x)


@dataclass(frozen=True)
class OptimizerSettings:
    """Adam at ``lr`` with ``betas``; ``schedule``: ``constant`` or ``cosine`` (a half cosine to 0 over the
    run's training steps, updated every step)."""

    lr: float = 1e-3
    betas: tuple[float, float] = (0.9, 0.999)
    schedule: str = "constant"

    def __post_init__(self):
        object.__setattr__(self, "betas", _tuple(self.betas))
        if self.schedule not in LR_SCHEDULES:
            raise ValueError(f"unknown task.optimizer.schedule '{self.schedule}' ({', '.join(LR_SCHEDULES)})")


@dataclass(frozen=True)
class PhaseSettings:
    """``use``: alpha and beta follow ``weights`` (``[{start, alpha, beta}, ...]``, starts in ``unit``:
    ``fraction`` of the run or ``epochs``; None: the thesis's phases) through the
    :class:`~lit3d.canonical.loss_phases.LossPhases` callback; else the constant ``alpha`` and ``beta``."""

    use: bool = True
    unit: str = "fraction"
    weights: tuple[Mapping, ...] | None = None
    alpha: float = 1000.0
    beta: float = 100.0

    def __post_init__(self):
        if self.weights is not None:
            object.__setattr__(self, "weights", tuple(dict(w) for w in self.weights))


@dataclass(frozen=True)
class WarpObjective:
    """The warp head's terms (:mod:`lit3d.canonical.warp_loss`), each ``<term>_weight`` times its loss: the
    flow's end-point distance on the visible pixels, the visibility on the canonical foreground and the flow's
    total variation (``smooth``)."""

    flow_weight: float = 0.0
    vis_weight: float = 0.0
    smooth_weight: float = 0.0


@dataclass(frozen=True)
class IdentityObjective:
    """A subject classifier (one linear layer, ``classes`` outputs) on the MSFE's fused latent, its
    cross-entropy x ``weight`` (``arch=recall``: the recall net's own logits; ``classes``: its subjects)."""

    weight: float = 0.0
    classes: int = 0


@dataclass(frozen=True)
class PanelSettings:
    """Validation panels (input | predicted | true | error) of ``n`` items every ``every_n_epochs`` (0: none)."""

    every_n_epochs: int = 1
    n: int = 4


def parse(cls, node, name: str):
    """``node`` (a mapping, None for the defaults, or already a ``cls``) as a ``cls``; ValueError naming
    ``task.<name>.<key>`` for a key ``cls`` does not have (:func:`lit3d.utils.settings_nodes.parse_node`)."""
    return parse_node(cls, node, f"task.{name}")
