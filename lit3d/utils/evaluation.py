"""What a task room's evaluator hands back after the test (interface: :mod:`lit3d.runtime.registry`), and
the evaluation settings older checkpoints still carry among the task's hyper-parameters."""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any


@dataclass
class Evaluation:
    """The result of ``protocol(task, datamodule, settings)``.

    Attributes:
        metrics: scalar metrics (``test/...``) added to the run's ``metrics.json``, on every rank.
        artefacts: in-memory results the same run's ``write_artefacts`` / ``write_figures`` use
            (e.g. the canonical held-out items, the quality leave-one-shape-out predictions);
            never written to ``metrics.json``.
    """

    metrics: dict[str, float] = field(default_factory=dict)
    artefacts: dict[str, Any] = field(default_factory=dict)


def legacy_settings(owner: str, legacy: Mapping[str, Any], moved: Mapping[str, Any]) -> dict[str, Any]:
    """The evaluation settings among an old checkpoint's hyper-parameters (``legacy``: what a task's
    constructor got beyond its own arguments), over ``moved`` (the keys the evaluation config node
    took from the task config, with the defaults the constructor had). ValueError naming the first
    key that is not one of them (a misspelt option, not an old checkpoint's)."""
    unknown = sorted(set(legacy) - set(moved))
    if unknown:
        raise ValueError(f"{owner}: unexpected keyword argument '{unknown[0]}'")
    return {**moved, **legacy}
