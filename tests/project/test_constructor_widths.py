"""No constructor of the package (``lit3d`` and ``datamodules``) takes more than :data:`WIDEST` named arguments:
settings travel as config nodes (frozen dataclasses: ``lit3d/*/settings.py``, ``datamodules/*/settings.py``)."""
from __future__ import annotations

import importlib
import inspect
import pkgutil

import datamodules
import lit3d

WIDEST = 15
ROOMS = (lit3d, datamodules)


def named_arguments(cls) -> list[str]:
    """The named constructor arguments of ``cls`` (``self``, ``*args`` and ``**kwargs`` not counted)."""
    return [p.name for p in inspect.signature(cls.__init__).parameters.values()
            if p.name != "self" and p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)]


def _classes() -> dict[str, type]:
    found = {}
    for pkg in ROOMS:
        for info in pkgutil.walk_packages(pkg.__path__, pkg.__name__ + "."):
            mod = importlib.import_module(info.name)
            for obj in vars(mod).values():
                if inspect.isclass(obj) and obj.__module__ == mod.__name__ and "__init__" in vars(obj):
                    found[f"{obj.__module__}.{obj.__qualname__}"] = obj
    return found


def widths() -> dict[str, int]:
    """Every constructor of the package by its named arguments, widest first."""
    out = {name: len(named_arguments(cls)) for name, cls in _classes().items()}
    return dict(sorted(out.items(), key=lambda kv: -kv[1]))


def test_no_constructor_is_wider_than_the_rule():
    found = widths()
    assert {"lit3d.canonical.module.CanonicalTask", "lit3d.completion.module.CompletionTask",
            "datamodules.completion.datamodule.CompletionDataModule",
            "datamodules.quality.datamodule.QualityDataModule", "lit3d.quality.module.QualityTask"} <= set(found)
    wide = {name: n for name, n in found.items() if n > WIDEST}
    assert not wide, f"constructors wider than {WIDEST} named arguments (group them into config nodes): {wide}"


if __name__ == "__main__":  # the widest constructors: python tests/project/test_constructor_widths.py
    for name, n in list(widths().items())[:8]:
        print(f"{n:3d}  {name}")
