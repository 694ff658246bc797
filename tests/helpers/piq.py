"""piq's own functions for the tests that check lit3d against piq, loaded without piq's package ``__init__``
(which imports torchvision, not installed: piq is installed with ``--no-deps``). Independent of
:func:`lit3d.metrics.image.colour_measures.piq_functions`, which the tests check."""
from __future__ import annotations

import importlib
import importlib.util
import sys
import types
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager

import pytest

SKIP_REASON = "piq is not installed (scripts/bootstrap.sh installs it: pip install --no-deps piq==0.8.0)"


@contextmanager
def piq_functions(names: Mapping[str, tuple[str, str]]) -> Iterator[dict[str, Callable]]:
    """``{key: piq function}`` for ``names`` ``{key: (module, function)}`` (e.g. ``{"fsim": ("fsim", "fsim")}``);
    skips the test when piq is not installed; ``sys.modules`` is as before afterwards."""
    spec = importlib.util.find_spec("piq")
    if spec is None:
        pytest.skip(SKIP_REASON)
    saved = {k: v for k, v in sys.modules.items() if k == "piq" or k.startswith("piq.")}
    for k in saved:
        del sys.modules[k]
    package = types.ModuleType("piq")  # the package without its __init__
    package.__path__ = list(spec.submodule_search_locations)
    sys.modules["piq"] = package
    try:
        yield {key: getattr(importlib.import_module(f"piq.{mod}"), fn) for key, (mod, fn) in names.items()}
    finally:
        for k in [k for k in sys.modules if k == "piq" or k.startswith("piq.")]:
            del sys.modules[k]
        sys.modules.update(saved)
