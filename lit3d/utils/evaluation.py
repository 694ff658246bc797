"""What a task room's evaluator hands back after the test (interface: :mod:`lit3d.cli.registry`)."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any


@dataclass
class Evaluation:
    """The result of ``protocol(task, datamodule)``.

    Attributes:
        metrics: scalar metrics (``test/...``) added to the run's ``metrics.json``, on every rank.
        artefacts: in-memory results the same run's ``write_artefacts`` / ``write_figures`` use
            (e.g. the canonical held-out items, the quality leave-one-shape-out predictions);
            never written to ``metrics.json``.
    """

    metrics: dict[str, float] = field(default_factory=dict)
    artefacts: dict[str, Any] = field(default_factory=dict)
