"""Data configs of the completion DataModule written before its settings became nodes (one flat mapping, as
old checkpoints and run configs hold them) turned into today's nodes
(:mod:`datamodules.completion.settings`).

    upgrade_data_config({"source": "installed", "sensor": "recgan", "views_per_shape": 4, "min_models": 8,
                         "categories": None, "compress": True, ...})
    -> {"source": "installed", "render": {"sensor": "recgan", "views_per_shape": 4}, "meshes": {"min_models": 8},
        "categories": {"seen": None}, "prepare": {"compress": True}, ...}

A config already in today's layout comes back unchanged; a key no version knew is kept, so the DataModule
names it.
"""
from __future__ import annotations

from collections.abc import Mapping

from lit3d.utils.settings_nodes import nest_flat_keys

# flat key -> (node, key in the node)
FLAT_DATA_KEYS = {
    **{k: ("render", k) for k in ("views_per_shape", "unseen_view_set", "render_factor", "sensor")},
    **{k: ("recgan", k) for k in ("val_fraction", "raw_res")},
    **{k: ("meshes", k) for k in ("model_split", "min_models", "up_axis", "procedural_share")},
    "prepare_workers": ("prepare", "workers"), "progress": ("prepare", "progress"),
    "skip_bad": ("prepare", "skip_bad"), "compress": ("prepare", "compress"),
    "categories": ("categories", "seen"), "unseen_categories": ("categories", "unseen"),
}


def is_flat(key: str, value) -> bool:
    """Whether ``key: value`` is a setting of the flat layout (``categories`` is a node today: a mapping)."""
    return key in FLAT_DATA_KEYS and not (key == "categories" and isinstance(value, Mapping))


def upgrade_data_config(cfg: Mapping) -> dict:
    """A completion data config with flat keys (see the module docstring) as nodes; today's layout unchanged."""
    return nest_flat_keys(cfg, FLAT_DATA_KEYS, is_flat)
