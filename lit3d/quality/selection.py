"""Sequential Forward Search, exactly as the thesis's Algorithm 4.1.

    Sel_F = {}
    repeat:
        f_next = none
        c_next = corr(Sel_F)            # correlation on the TRAINING set when trained with Sel_F
        for f in F:
            if f not in Sel_F:
                c_f = corr(Sel_F + {f})
                if c_f > c_next:
                    f_next, c_next = f, c_f
        if f_next: Sel_F = Sel_F + {f_next}
    until f_next is none

``corr`` is any function of a feature set that only looks at training data: the
caller binds it to the training folds (see :func:`lit3d.quality.protocol.training_corr`),
so the search never sees a test shape. ``corr({})`` is taken as ``-inf`` (a model
with no input has no correlation to speak of), so the first step always adds the
best single feature. Ties keep the earlier feature in ``F``'s order (strict ``>``).

The search calls ``corr_many`` with all candidate sets of one step at once so that
a scorer can train the candidate models together; ``corr(Sel_F)`` is the value
recorded when ``Sel_F`` was chosen (deterministic training makes recomputing it
give the same number).

Two optional limits (off by default, so the default *is* Algorithm 4.1):
``max_features`` stops after that many features; ``min_gain`` requires
``c_f > c_next + min_gain``.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field


@dataclass
class SFSResult:
    """Selected features (in the order added) and the training correlation after each step."""

    selected: list[str]
    scores: list[float]
    # every step: {candidate feature: corr(Sel_F + {candidate})}
    steps: list[dict[str, float]] = field(default_factory=list)

    @property
    def best_score(self) -> float:
        return self.scores[-1] if self.scores else -math.inf

    def to_dict(self) -> dict:
        return {"selected": list(self.selected), "scores": [float(s) for s in self.scores]}


CorrMany = Callable[[list[list[str]]], Sequence[float]]


def sequential_forward_search(
    features: Sequence[str],
    corr_many: CorrMany,
    max_features: int | None = None,
    min_gain: float = 0.0,
    keep_steps: bool = False,
) -> SFSResult:
    """Greedy forward selection (Algorithm 4.1).

    features:   the list F of candidate feature names (order breaks ties).
    corr_many:  list of feature sets -> their training-set correlations (same order).
    """
    features = list(dict.fromkeys(features))
    selected: list[str] = []
    scores: list[float] = []
    steps: list[dict[str, float]] = []
    c_current = -math.inf  # corr({})
    while True:
        if max_features is not None and len(selected) >= max_features:
            break
        candidates = [f for f in features if f not in selected]
        if not candidates:
            break
        values = [float(v) for v in corr_many([selected + [f] for f in candidates])]
        if len(values) != len(candidates):
            raise ValueError(f"corr_many returned {len(values)} values for {len(candidates)} feature sets")
        f_next, c_next = None, c_current
        for f, c_f in zip(candidates, values):
            if not math.isnan(c_f) and c_f > c_next + (min_gain if f_next is None else 0.0):
                f_next, c_next = f, c_f
        if keep_steps:
            steps.append(dict(zip(candidates, values)))
        if f_next is None:
            break
        selected.append(f_next)
        scores.append(c_next)
        c_current = c_next
    return SFSResult(selected, scores, steps)
