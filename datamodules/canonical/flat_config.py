"""Data configs of the canonical DataModule written before its settings became nodes (one flat mapping of
45 keys, as old checkpoints, run configs and ``heldout.npz`` files hold them) turned into today's nodes.

    upgrade_data_config({"source": "tosca", "root": R, "split": "pose", "fold": 1, "flip_lr": True, ...})
    -> {"source": {"kind": "tosca", ...}, "root": R, "split": {"mode": "pose", "fold": 1, ...},
        "training": {"flip_lr": True, ...}, ...}

A config that already has nodes (``source`` a mapping) is returned unchanged. Flat keys of another
source than the config's (e.g. ``kinds`` in a TOSCA config, where they were ignored) are dropped; a key
no version knew is kept, so the DataModule names it.
"""
from __future__ import annotations

import dataclasses
from collections.abc import Mapping

from datamodules.canonical.settings import (SOURCE_SETTINGS, RenderSettings, SplitSettings, TrainingSettings, as_node,
                                            parse, parse_source)

# flat key -> (node, key in the node)
RENDER = {k: ("render", k) for k in ("azimuths", "view_mode", "scale_mode", "flow_targets", "forward_flow")}
SPLIT = {"split": ("split", "mode"), "split_seed": ("split", "seed"),
         **{k: ("split", k) for k in ("n_folds", "fold", "val_per_subject", "max_val_items", "val_subjects",
                                     "val_poses", "train_pose_fraction", "eval_views")}}
TRAINING = {k: ("training", k) for k in ("flip_lr", "roll_deg", "blend_poses", "balance_subjects", "batch_poses")}
MOVED = {**RENDER, **SPLIT, **TRAINING}
SOURCE_KEYS = {f.name for c in SOURCE_SETTINGS.values() for f in dataclasses.fields(c)} - {"seed"}


def upgrade_data_config(cfg: Mapping) -> dict:
    """A canonical data config with flat keys (see the module docstring) as nodes; a nested one unchanged."""
    cfg = dict(cfg)
    if isinstance(cfg.get("source"), Mapping):
        return cfg
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
    return out


# the DataModule's flat settings and their defaults (as its constructor has them)
FLAT_DEFAULTS = {"root": None, "seed": 42, "batch_size": 8, "num_workers": 0, "prepare_workers": 0, "skip_bad": False,
                 "phenotype_targets": False}


def full_data_config(cfg: Mapping) -> dict:
    """A data config of either layout with every setting spelt out (the nodes parsed, defaults filled in): two
    configs of one data compare equal however much of it each wrote down."""
    cfg = upgrade_data_config(cfg)
    out = {**FLAT_DEFAULTS, **cfg, "source": as_node(parse_source(cfg.get("source") or {"kind": "synth"}))}
    for name, cls in (("render", RenderSettings), ("split", SplitSettings), ("training", TrainingSettings)):
        out[name] = as_node(parse(cls, cfg.get(name), name))
    return out
