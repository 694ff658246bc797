"""Every task room's evaluator module provides the interface :mod:`lit3d.runtime.registry` lists, with the
arguments it names first (more only with defaults): ``lit3d-eval`` and ``lit3d-train`` call them without
probing."""
from __future__ import annotations

import inspect

import pytest

import lit3d.runtime.registry as registry
from lit3d.runtime.registry import EVALUATORS, evaluator_module

INTERFACE = {
    "prepare": ["task", "settings"],
    "protocol": ["task", "datamodule", "settings"],
    "validation_protocol": ["trainer", "task", "datamodule", "settings"],
    "write_artefacts": ["evaluation", "out_dir"],
    "write_results": ["metrics", "out_dir"],
    "write_figures": ["task", "datamodule", "out_dir", "n", "evaluation"],
}


@pytest.mark.parametrize("task_name", sorted(EVALUATORS))
def test_every_evaluator_provides_the_registry_interface(task_name):
    module = evaluator_module(task_name)
    for name, params in INTERFACE.items():
        assert callable(getattr(module, name, None)), f"{module.__name__}.{name} missing"
        given = list(inspect.signature(getattr(module, name)).parameters.values())
        assert [p.name for p in given[:len(params)]] == params, f"{module.__name__}.{name}"
        assert all(p.default is not p.empty for p in given[len(params):]), f"{module.__name__}.{name}: more required"


def test_the_registry_doc_lists_the_interface():
    assert all(f"``{name}(" in registry.__doc__ for name in INTERFACE)


def test_an_unknown_task_names_the_known_ones():
    with pytest.raises(KeyError, match="unknown task 'nope' \\(known: body, canonical, completion, quality\\)"):
        evaluator_module("nope")
