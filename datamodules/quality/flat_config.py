"""Data configs of the quality DataModule written before its settings became nodes (one flat mapping, as old
checkpoints' data configs and DataModule hyper-parameters hold them) turned into today's nodes
(:mod:`datamodules.quality.settings`).

    upgrade_data_config({"source": "synth", "shapes": [...], "n_levels": 2, "feature_options": {...},
                         "feature_workers": 4, "test_shapes": None, ...})
    -> {"source": "synth", "synth": {"shapes": [...], "n_levels": 2}, "feature_tables": {"options": {...}, "workers": 4},
        "split": {"test_shapes": None}, ...}

A config already in today's layout comes back unchanged; a key no version knew is kept, so the DataModule
names it.
"""
from __future__ import annotations

from collections.abc import Mapping

from lit3d.utils.settings_nodes import nest_flat_keys

# flat key -> (node, key in the node)
FLAT_DATA_KEYS = {
    **{k: ("synth", k) for k in ("shapes", "user_mesh_dir", "distortions", "levels", "n_levels", "subdivisions")},
    "feature_fn": ("feature_tables", "fn"), "feature_options": ("feature_tables", "options"),
    "feature_workers": ("feature_tables", "workers"),
    **{k: ("split", k) for k in ("test_shapes", "val_shapes", "groups")},
}


def upgrade_data_config(cfg: Mapping) -> dict:
    """A quality data config with flat keys (see the module docstring) as nodes; today's layout unchanged."""
    return nest_flat_keys(cfg, FLAT_DATA_KEYS)
