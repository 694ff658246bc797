"""One line for a misspelt option, naming the option that was probably meant.

- ``trainer.max_epoch=3`` does not compose (no such key): Hydra's own hint, "use +trainer.max_epoch=3",
  leads to the second case; :func:`misspelt_key` names ``trainer.max_epochs`` instead.
- ``+trainer.max_epoch=3`` composes, then the object built from the node (``lightning``'s ``Trainer``)
  refuses the argument; :func:`instantiation_problem` turns Hydra's multi-line error into one line
  naming the key and the target's closest argument.
"""
from __future__ import annotations

import difflib
import inspect
import re
from collections.abc import Callable, Sequence

from omegaconf import DictConfig, OmegaConf

_NOT_OVERRIDABLE = re.compile(r"Could not override '(?P<key>[^']+)'")
_UNEXPECTED = re.compile(r"unexpected keyword argument '(?P<arg>[^']+)'")
_TARGET = re.compile(r"call to target '(?P<target>[^']+)'")
_FULL_KEY = re.compile(r"full_key: (?P<key>\S+)")


def _closest(word: str, options: Sequence[str]) -> str | None:
    found = difflib.get_close_matches(word, list(options), n=1, cutoff=0.6)
    return found[0] if found else None


def misspelt_key(message: str, args: Sequence[str], compose: Callable[[list[str]], DictConfig]) -> str | None:
    """For Hydra's "Could not override 'KEY'" ``message``: one line naming the existing key closest to
    KEY under its parent node, or None (no such message, or no close key). ``compose(overrides)``: the
    command's config composed with those overrides (here without the misspelt one)."""
    m = _NOT_OVERRIDABLE.search(message)
    if not m:
        return None
    key = m.group("key")
    given = next((a for a in args if a.split("=", 1)[0].lstrip("+~") == key), None)
    try:
        cfg = compose([a for a in args if a is not given])
    except Exception:  # something else does not compose either: Hydra's message stands
        return None
    parent, _, leaf = key.rpartition(".")
    node = OmegaConf.select(cfg, parent, default=None) if parent else cfg
    if not isinstance(node, DictConfig):
        return None
    near = _closest(leaf, [str(k) for k in node.keys()])
    if near is None:
        return None
    value = given.split("=", 1)[1] if given and "=" in given else "..."
    meant = f"{parent}.{near}" if parent else near
    return (f"Could not override '{key}': {given or key} names no key of the config; did you mean {meant}={value}? "
            f"(a leading + adds a key the config lacks, and only works where the code reading the node accepts it)")


def instantiation_problem(exc: BaseException) -> str | None:
    """One line for Hydra's error when a config node's target refuses an argument (``+trainer.max_epoch=3``:
    ``Trainer.__init__() got an unexpected keyword argument 'max_epoch'``), naming the key and the target's
    closest argument; None for any other error."""
    text = f"{exc} {exc.__cause__ or ''}"
    arg, target = _UNEXPECTED.search(text), _TARGET.search(text)
    if arg is None or target is None or type(exc).__name__ != "InstantiationException":
        return None
    full = _FULL_KEY.search(text)
    node = full.group("key") if full else ""
    key = f"{node}.{arg.group('arg')}" if node else arg.group("arg")
    near = None
    try:
        from hydra.utils import get_object

        params = inspect.signature(get_object(target.group("target"))).parameters
        near = _closest(arg.group("arg"), [p for p in params if p != "self"])
    except Exception:  # the target cannot be inspected: no suggestion
        pass
    hint = f"; did you mean {node + '.' if node else ''}{near}?" if near else ""
    return f"{key}: not an argument of {target.group('target')}{hint}"


__all__ = ["instantiation_problem", "misspelt_key"]
