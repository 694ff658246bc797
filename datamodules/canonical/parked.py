"""The canonical options measured and not adopted, removed from the product: where their code is (the git tag
:data:`PARKED_TAG`, studies/canonical/LOG.md 2026-11-29) and the rule that takes them out of an old config.

    drop_parked({"render": {"flow_targets": True, "forward_flow": False}}, PARKED_DATA, "data.", "run/config.yaml")
    -> {"render": {"flow_targets": True}}
    drop_parked({"render": {"forward_flow": True}}, PARKED_DATA, "data.", "run/config.yaml")
    -> ParkedOptionError: run/config.yaml: data.render.forward_flow=True is a parked canonical option (...) at git tag ...

The data's parked options are here (:data:`PARKED_DATA`, dropped by
:func:`datamodules.canonical.flat_config.upgrade_data_config`); the task's are in
:mod:`lit3d.canonical.checkpoint_upgrade`.
"""
from __future__ import annotations

from collections.abc import Mapping

from lit3d.utils.errors import Lit3dError

PARKED_TAG = "parked-canonical-options"
ANY = object()  # a parked key dropped whatever its value (it acted only with another key's weight > 0)
# a parked data option (dotted, in the layout of nodes) -> the value at which it was off: the splat head's forward
# flow targets, the phenotype regression's targets, the contrastive term's pose-grouped batches
PARKED_DATA = {"render.forward_flow": False, "phenotype_targets": False, "training.batch_poses": 0}


class ParkedOptionError(Lit3dError, ValueError):
    """A checkpoint or config that used an option removed from the product (measured and not adopted)."""


def refuse(source: str | None, key: str, value) -> ParkedOptionError:
    """The one-line error for ``key=value`` (a parked option in use) of the file ``source`` (None: not named)."""
    where = f"{source}: " if source else ""
    return ParkedOptionError(f"{where}{key}={value!r} is a parked canonical option (measured and not adopted, removed); "
                             f"this needs the code at git tag {PARKED_TAG}")


def drop_parked(config: Mapping, parked: Mapping, prefix: str, source: str | None = None,
                values: Mapping | None = None) -> dict:
    """``config`` (nested mappings) without the keys of ``parked`` (dotted) that hold their default (or any value
    for :data:`ANY`), nor nodes left empty by that; :class:`ParkedOptionError` naming ``source`` and
    ``<prefix><key>`` for one at another value, or a key of ``values`` (dotted key -> its parked values) at one
    of its parked values."""
    values = values or {}

    def walk(node: Mapping, path: str) -> dict:
        out = {}
        for key, value in node.items():
            dotted = f"{path}{key}"
            if dotted in parked:
                default = parked[dotted]
                if default is not ANY and not _same(value, default):
                    raise refuse(source, prefix + dotted, value)
                continue
            if dotted in values and value in values[dotted]:
                raise refuse(source, prefix + dotted, value)
            if isinstance(value, Mapping) and value and any(k.startswith(dotted + ".") for k in (*parked, *values)):
                value = walk(value, dotted + ".")
                if not value:
                    continue  # a node of parked keys only (phenotype, contrastive)
            out[key] = value
        return out
    return walk(config, "")


def _same(value, default) -> bool:
    """``value`` equals ``default`` (numbers by value: 1 == 1.0)."""
    if isinstance(default, (int, float)) and not isinstance(default, bool) and isinstance(value, (int, float)):
        return float(value) == float(default)
    return value == default
