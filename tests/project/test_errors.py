"""One root for lit3d's errors (``lit3d.utils.errors.Lit3dError``), no ``assert`` for user input, and
config errors told apart from bugs when a task or DataModule is built."""
from __future__ import annotations

import ast
import importlib
import inspect
import pkgutil

import numpy as np
import pytest

import datamodules
import lit3d
from lit3d.runtime.build import _construct
from lit3d.runtime.errors import UserError
from lit3d.runtime.config_checks import config_problem
from lit3d.utils.errors import Lit3dError
from tests.helpers.paths import REPO

SIGNALS = {"Stopped", "Interrupted", "StopRequested"}  # signals, not errors (lit3d.cli.about, .common, lit3d.utils.stops)


def _modules():
    for pkg in (lit3d, datamodules):
        for info in pkgutil.walk_packages(pkg.__path__, pkg.__name__ + "."):
            if info.name.startswith("lit3d.api") or info.name.endswith("__main__"):
                continue
            yield importlib.import_module(info.name)


def test_every_error_class_is_a_lit3d_error():
    found, stray = [], []
    for module in _modules():
        for name, cls in inspect.getmembers(module, inspect.isclass):
            if cls.__module__ != module.__name__ or not issubclass(cls, BaseException) or issubclass(cls, Warning):
                continue
            found.append(name)
            if name not in SIGNALS and not issubclass(cls, Lit3dError):
                stray.append(f"{module.__name__}.{name}")
    assert {"DataError", "OutputError", "UserError", "InputError", "ShapeError"} <= set(found)
    assert not stray, f"error classes outside Lit3dError: {stray}"


def test_no_assert_in_the_package():
    """``python -O`` drops asserts: user input and leak checks must raise."""
    hits = []
    for root in ("lit3d", "datamodules"):
        for path in (REPO / root).rglob("*.py"):
            tree = ast.parse(path.read_text(), str(path))
            hits += [f"{path.relative_to(REPO)}:{n.lineno}" for n in ast.walk(tree) if isinstance(n, ast.Assert)]
    assert not hits, hits


class _Net:
    def __init__(self, width: int = 4):
        if width <= 0:
            raise ValueError(f"width must be > 0, got {width}")  # an argument check (but in tests/, not lit3d)
        self.w = np.zeros(width)


def test_config_errors_become_one_line_and_bugs_keep_their_traceback():
    from datamodules.cache import DataError

    def bad_value():
        raise DataError("data.source.n_poses=0: need at least one pose")

    with pytest.raises(UserError, match="data config: data.source.n_poses=0"):
        _construct("data", bad_value)
    with pytest.raises(UserError, match="task config: .*unexpected keyword argument 'widht'"):
        _construct("task", lambda: _Net(widht=3))
    # a ValueError raised inside a library (numpy here) is a bug, not a config value: passed on as is
    with pytest.raises(ValueError, match="negative dimensions") as info:
        _construct("task", lambda: np.zeros(-1))
    assert not isinstance(info.value, UserError) and not config_problem(info.value)
