"""Data configs of the canonical DataModule written before its settings became nodes (one flat mapping of
45 keys, as old checkpoints, run configs and ``heldout.npz`` files hold them) turned into today's nodes.

    upgrade_data_config({"source": "tosca", "root": R, "split": "pose", "fold": 1, "flip_lr": True, ...})
    -> {"source": {"kind": "tosca", ...}, "root": R, "split": {"mode": "pose", "fold": 1, ...},
        "training": {"flip_lr": True, ...}, ...}

A config that already has nodes (``source`` a mapping) keeps its layout. Flat keys of another source than
the config's (e.g. ``kinds`` in a TOSCA config, where they were ignored) are dropped; a key no version knew is
kept, so the DataModule names it. Either layout loses the parked options at their defaults
(:data:`datamodules.canonical.parked.PARKED_DATA`); one at another value is a
:class:`~datamodules.canonical.parked.ParkedOptionError` naming the file, the key and the git tag of its code.
"""
from __future__ import annotations

import dataclasses
from collections.abc import Mapping

from datamodules.canonical.parked import PARKED_DATA, drop_parked
from datamodules.canonical.settings import (SOURCE_SETTINGS, RenderSettings, SplitSettings, TrainingSettings, as_node,
                                            parse, parse_source)

# flat key -> (node, key in the node); forward_flow and batch_poses: parked (moved, then dropped or refused)
RENDER = {k: ("render", k) for k in ("azimuths", "view_mode", "scale_mode", "flow_targets", "forward_flow")}
SPLIT = {"split": ("split", "mode"), "split_seed": ("split", "seed"),
         **{k: ("split", k) for k in ("n_folds", "fold", "val_per_subject", "max_val_items", "val_subjects",
                                     "val_poses", "train_pose_fraction", "eval_views")}}
TRAINING = {k: ("training", k) for k in ("flip_lr", "roll_deg", "blend_poses", "balance_subjects", "batch_poses")}
MOVED = {**RENDER, **SPLIT, **TRAINING}
SOURCE_KEYS = {f.name for c in SOURCE_SETTINGS.values() for f in dataclasses.fields(c)} - {"seed"}


def upgrade_data_config(cfg: Mapping, source: str | None = None) -> dict:
    """A canonical data config with flat keys (see the module docstring) as nodes, without the parked options
    at their defaults; a nested one keeps its layout. ``source``: the file it came from, named by the
    :class:`~datamodules.canonical.parked.ParkedOptionError` of a parked option in use."""
    cfg = dict(cfg)
    if isinstance(cfg.get("source"), Mapping):
        return drop_parked(cfg, PARKED_DATA, "data.", source)
    kind = cfg.pop("source", "synth")
    fields = {f.name for f in dataclasses.fields(SOURCE_SETTINGS[kind])} if kind in SOURCE_SETTINGS else set()
    out: dict = {"source": {"kind": kind}}
    for key, value in cfg.items():
        if key == "seed":  # the DataModule's (and, below, the synth figures')
            out[key] = value
        elif key in MOVED:
            node, name = MOVED[key]
            out.setdefault(node, {})[name] = value
        elif key in fields:
            out["source"][key] = value
        elif key not in SOURCE_KEYS:
            out[key] = value
    if "seed" in fields:  # the synth figures were drawn with the DataModule's seed
        out["source"]["seed"] = cfg.get("seed", 42)
    return drop_parked(out, PARKED_DATA, "data.", source)


# the DataModule's flat settings and their defaults (as its constructor has them)
FLAT_DEFAULTS = {"root": None, "seed": 42, "batch_size": 8, "num_workers": 0, "prepare_workers": 0, "skip_bad": False}


def full_data_config(cfg: Mapping, source: str | None = None) -> dict:
    """A data config of either layout with every setting spelt out (the nodes parsed, defaults filled in): two
    configs of one data compare equal however much of it each wrote down (``source``: the file it came from,
    :func:`upgrade_data_config`)."""
    cfg = upgrade_data_config(cfg, source)
    out = {**FLAT_DEFAULTS, **cfg, "source": as_node(parse_source(cfg.get("source") or {"kind": "synth"}))}
    for name, cls in (("render", RenderSettings), ("split", SplitSettings), ("training", TrainingSettings)):
        out[name] = as_node(parse(cls, cfg.get(name), name))
    return out
