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


def nest_flat_keys(cfg: Mapping, table: Mapping[str, tuple[str, str]], moves=None) -> dict:
    """``cfg`` with its old flat keys moved into today's nodes: ``table`` maps a flat key to ``(node, name)``;
    ``moves(key, value)`` (default: the key is in ``table``) says whether an entry moves (a key that is a node
    today as well as a flat key once). Values already in a node are kept, the moved ones set over them; a
    config in today's layout comes back unchanged. Every checkpoint upgrade of a settings node uses it."""
    out: dict = {}
    moved: dict[str, dict] = {}
    for key, value in cfg.items():
        if moves(key, value) if moves is not None else key in table:
            node, name = table[key]
            moved.setdefault(node, {})[name] = value
        else:
            out[key] = value
    for node, values in moved.items():
        out[node] = {**dict(out.get(node) or {}), **values}
    return out
