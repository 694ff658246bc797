"""Train/val/test splits of canonical-form pairs (subject, pose); see ``split`` in
:mod:`datamodules.canonical`.

    subject_pose  subjects and poses are each dealt into ``n_folds`` groups (seeded); fold f
                  tests subject group f x pose group f and trains on the other subjects x other
                  poses only (no test subject and no test pose in training). Validation, with
                  ``val_subjects`` = N: N further subjects (not tested, not trained on) in the
                  training poses, so checkpoints and settings are chosen on people the test never
                  sees; with ``val_subjects`` null (the old rule): the items that share exactly one
                  of subject and pose with the test (test subjects in training poses among them).
    pose          (TOSCA: one subject per class) every subject's non-canonical poses are dealt
                  into ``n_folds`` groups; fold f tests group f; ``val_per_subject`` training
                  poses per subject go to validation.
    all           evaluation only (FAUST, TOSCA's humans as new subjects): every item is a test
                  item; train and val are empty.
"""
from __future__ import annotations

from collections import Counter
from collections.abc import Sequence

import numpy as np

from datamodules.cache import DataError
from datamodules.canonical.settings import VAL_POSES

CANONICAL_SPLITS = ("train", "val", "test")
OWN_POSE_BASE = 20_000  # pose ids from here on: a subject's own training-only poses (synth data.source.own_poses)


def deal(items: Sequence, n_groups: int, seed: int) -> list[list]:
    """Shuffle ``items`` (seeded) and deal them round-robin into ``n_groups`` groups."""
    order = list(items)
    np.random.default_rng(seed).shuffle(order)
    return [sorted(order[g::n_groups], key=str) for g in range(n_groups)]


def split_subject_pose(subjects, poses, n_folds: int, fold: int, seed: int,
                       val_subjects: int | None = None) -> dict[str, list[tuple]]:
    """Strict split: test = S_f x P_f. ``val_subjects`` = N: val = S_v x (P \\ P_f) for N subjects S_v
    drawn (seeded) outside S_f, train = (S \\ S_f \\ S_v) x (P \\ P_f). None: train = (S \\ S_f) x
    (P \\ P_f), val = the mixed rest."""
    if n_folds < 2:
        raise DataError("subject_pose split needs n_folds >= 2")
    if len(subjects) < n_folds or len(poses) < n_folds:
        raise DataError(f"subject_pose split with {n_folds} folds needs at least {n_folds} subjects and poses "
                        f"(have {len(subjects)} subjects, {len(poses)} poses)")
    sg = deal(subjects, n_folds, seed)[fold % n_folds]
    pg = deal(poses, n_folds, seed + 1)[fold % n_folds]
    out = {k: [] for k in CANONICAL_SPLITS}
    if val_subjects is not None:
        rest = [s for s in subjects if s not in sg]
        if not 1 <= int(val_subjects) < len(rest):
            raise DataError(f"val_subjects={val_subjects}: needs 1 .. {len(rest) - 1} (subjects outside the test "
                            f"group: {len(rest)})")
        np.random.default_rng(seed + 2).shuffle(rest)
        vg = set(rest[:int(val_subjects)])
        for s in subjects:
            for p in poses:
                if s in sg and p in pg:
                    out["test"].append((s, p))
                elif s not in sg and p not in pg:  # the rest (a test subject or a test pose alone) is unused
                    out["val" if s in vg else "train"].append((s, p))
        return out
    for s in subjects:
        for p in poses:
            a, b = s in sg, p in pg
            out["test" if a and b else "train" if not (a or b) else "val"].append((s, p))
    return out


def split_pose(subject_poses: dict[str, list], n_folds: int, fold: int, seed: int,
               val_per_subject: int = 1) -> dict[str, list[tuple]]:
    """Per subject: poses dealt into folds; fold f -> test, ``val_per_subject`` others -> val.
    Every pose is tested by exactly one of the ``n_folds`` folds."""
    out = {k: [] for k in CANONICAL_SPLITS}
    for i, (s, poses) in enumerate(sorted(subject_poses.items())):
        if len(poses) < 2:
            out["train"] += [(s, p) for p in poses]
            continue
        groups = deal(poses, min(n_folds, len(poses)), seed + i)
        # fewer poses than folds: the later folds test none of this subject's poses (each pose is
        # held out by exactly one fold, so the pooled protocol sees it once)
        test = groups[fold % n_folds] if fold % n_folds < len(groups) else []
        rest = [p for p in poses if p not in test]
        val = rest[:val_per_subject] if len(rest) > val_per_subject else []
        out["test"] += [(s, p) for p in test]
        out["val"] += [(s, p) for p in val]
        out["train"] += [(s, p) for p in rest if p not in val]
    return out


def thin_training(train: Sequence[tuple], fraction: float, seed: int) -> list[tuple]:
    """``fraction`` of each subject's training ``(subject, pose)`` pairs, at least one per subject,
    drawn with ``seed`` (the learning-curve knob ``train_pose_fraction``; 1 keeps every pair)."""
    if not 0 < float(fraction) <= 1:
        raise DataError(f"train_pose_fraction must be in (0, 1], got {fraction}")
    if float(fraction) == 1:
        return list(train)
    by_subject: dict[str, list] = {}
    for s, p in train:
        by_subject.setdefault(s, []).append(p)
    keep = set()
    for i, (s, poses) in enumerate(sorted(by_subject.items())):
        order = list(poses)
        np.random.default_rng(seed + i).shuffle(order)
        keep |= {(s, p) for p in order[:max(1, round(float(fraction) * len(order)))]}
    return [sp for sp in train if sp in keep]


def fold_pairs(subject_poses: dict[str, list], mode: str, n_folds: int, fold: int, seed: int,
               val_per_subject: int = 1, val_subjects: int | None = None,
               val_poses: str = "training") -> dict[str, list[tuple]]:
    """``{split: [(subject, pose), ...]}`` of fold ``fold`` under split ``mode`` (:data:`SPLIT_MODES`)
    for ``subject_poses`` ``{subject: [pose, ...]}`` (only the poses each subject has). Pose ids from
    :data:`OWN_POSE_BASE` on (a subject's own poses) are left out of the split and added to the training
    pairs of the subjects that train: never tested. ``val_poses``: ``training`` validates the validation
    subjects in the shared training poses; ``own`` in their own poses instead, which no training pair has
    (new subjects in new poses, as the test)."""
    if val_poses not in VAL_POSES:
        raise DataError(f"val_poses must be one of {', '.join(VAL_POSES)}, got '{val_poses}'")
    if val_poses == "own" and val_subjects is None:
        raise DataError("val_poses=own needs validation subjects of their own (data.split.val_subjects=N)")
    own = {s: [p for p in ps if p >= OWN_POSE_BASE] for s, ps in subject_poses.items()}
    if any(own.values()):
        shared = {s: [p for p in ps if p < OWN_POSE_BASE] for s, ps in subject_poses.items()}
        pairs = fold_pairs(shared, mode, n_folds, fold, seed, val_per_subject, val_subjects)
        training = sorted({s for s, _ in pairs["train"]})
        pairs["train"] = pairs["train"] + [(s, p) for s in training for p in own[s]]
        if val_poses == "own":
            pairs["val"] = [(s, p) for s in sorted({s for s, _ in pairs["val"]}) for p in own[s]]
        return pairs
    if val_poses == "own":
        raise DataError("val_poses=own needs subjects with poses of their own (synth data.source.own_poses > 0)")
    if mode == "all":
        return {"train": [], "val": [], "test": [(s, p) for s, ps in sorted(subject_poses.items()) for p in ps]}
    if mode == "subject_pose":
        all_poses = sorted({p for ps in subject_poses.values() for p in ps})
        pairs = split_subject_pose(list(subject_poses), all_poses, n_folds, fold, seed, val_subjects)
        return {k: [(s, p) for s, p in v if p in subject_poses[s]] for k, v in pairs.items()}
    return split_pose(subject_poses, n_folds, fold, seed, val_per_subject)


def split_counts(records: Sequence[dict], categories: dict[str, str]) -> dict:
    """Items, subjects, poses and items per category of one split's ``{"subject", "pose", ...}`` records."""
    return {"items": len(records), "subjects": len({r["subject"] for r in records}),
            "poses": len({r["pose"] for r in records}),
            "per_category": dict(Counter(categories.get(r["subject"], r["subject"]) for r in records))}
