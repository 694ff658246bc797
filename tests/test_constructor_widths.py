"""The canonical task's constructors stay narrow: settings travel as config nodes (frozen dataclasses), so no
class of the canonical rooms takes more than :data:`WIDEST` named arguments."""
from __future__ import annotations

import importlib
import inspect
import pkgutil

import datamodules.canonical
import lit3d.canonical

WIDEST = 15
ROOMS = (lit3d.canonical, datamodules.canonical)


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


def test_no_canonical_constructor_is_wider_than_the_rule():
    classes = _classes()
    assert {"lit3d.canonical.module.CanonicalTask", "lit3d.canonical.nets.CanonicalNet",
            "datamodules.canonical.datamodule.CanonicalDataModule"} <= set(classes)
    wide = {name: len(named_arguments(cls)) for name, cls in classes.items() if len(named_arguments(cls)) > WIDEST}
    assert not wide, f"constructors wider than {WIDEST} named arguments (group them into config nodes): {wide}"
