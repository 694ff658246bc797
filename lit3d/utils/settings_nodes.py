"""Config nodes parsed into frozen dataclasses: one rule for every task's settings nodes.

    parse_node(WarpSettings, cfg.task.warp, "task.warp", ValueError)   # -> WarpSettings(...)
"""
from __future__ import annotations

import dataclasses
from collections.abc import Mapping


def parse_node(cls, node: Mapping | None, where: str, error: type[Exception] = ValueError):
    """``node`` (a mapping, None for the defaults, or already a ``cls``) as a ``cls``; ``error`` naming
    ``<where>.<key>`` for the first key ``cls`` does not have, with the keys it has."""
    if isinstance(node, cls):
        return node
    node = dict(node or {})
    fields = [f.name for f in dataclasses.fields(cls)]
    unknown = [k for k in node if k not in fields]
    if unknown:
        raise error(f"{where}.{unknown[0]}: not a setting of {where} ({', '.join(fields) or 'it has none'})")
    return cls(**node)
