"""The ShapeNet categories of the shape-completion experiments (thesis ch. 3, 3D-RecGAN++ data),
defined here once.

Seen categories are those the completion networks train on; the classifier's labels index
into :data:`SEEN_CATEGORIES`, so its order is part of every trained model. Unseen
categories appear only in the ``test_unseen`` (same view, thesis table 3.6) and ``test_unseen_cross``
(cross view, table 3.5) splits. The same
names key the synthetic shape generators, the 3D-RecGAN++ folders and the per-category
metrics and tables.

Why a shared room (``lit3d.utils``): the data side (``datamodules``) and the task room
(``lit3d.completion``) both need the names, and datamodules may not import a task room.

Why the YAML configs hold no list: ``categories`` and ``unseen_categories`` in
``conf/task/completion.yaml`` and ``conf/data/{completion_synth,recgan}.yaml`` default to
``null``, read as "all of them" by :func:`select_seen_categories` /
:func:`select_unseen_categories`.
A user may still pick a subset (``data.categories.seen=[chair]``); it is validated against the
lists here, so a typo fails at start-up instead of yielding an empty split.
"""
from __future__ import annotations

from collections.abc import Sequence

SEEN_CATEGORIES: tuple[str, ...] = ("bench", "chair", "couch", "table")
UNSEEN_CATEGORIES: tuple[str, ...] = ("car", "faucet", "firearm", "guitar", "monitor", "plane")
# other spellings of a category in 3D-RecGAN++ / ShapeNet folder names (the older release says "coach")
CATEGORY_ALIASES: dict[str, str] = {
    "coach": "couch", "sofa": "couch",
    "airplane": "plane", "aeroplane": "plane", "airplanes": "plane",
    "gun": "firearm", "rifle": "firearm", "pistol": "firearm", "handgun": "firearm",
    "display": "monitor", "tv": "monitor", "car_ex": "car", "tap": "faucet",
}


def _subset(chosen: Sequence[str] | None, known: tuple[str, ...], what: str) -> tuple[str, ...]:
    if chosen is None:
        return known
    chosen = tuple(str(c) for c in chosen)
    bad = [c for c in chosen if c not in known]
    if bad:
        raise ValueError(f"{what}: unknown categories {bad}; known: {list(known)}")
    return chosen


def select_seen_categories(chosen: Sequence[str] | None = None) -> tuple[str, ...]:
    """``chosen`` checked against :data:`SEEN_CATEGORIES` (``None``: all of them, in that order).

    Raises:
        ValueError: naming the unknown categories.
    """
    return _subset(chosen, SEEN_CATEGORIES, "categories")


def select_unseen_categories(chosen: Sequence[str] | None = None) -> tuple[str, ...]:
    """``chosen`` checked against :data:`UNSEEN_CATEGORIES` (``None``: all of them, in that order).

    Raises:
        ValueError: naming the unknown categories.
    """
    return _subset(chosen, UNSEEN_CATEGORIES, "unseen_categories")
