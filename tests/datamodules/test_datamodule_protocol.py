"""Every task's DataModule conforms to :class:`datamodules.protocol.InspectableDataModule`: the
``describe()`` / ``show(n, path)`` interface that ``lit3d-data`` uses, declared once."""
from __future__ import annotations

import inspect

import pytest

from datamodules.body import BodyDataModule
from datamodules.canonical import CanonicalDataModule
from datamodules.completion import CompletionDataModule
from datamodules.protocol import InspectableDataModule
from datamodules.quality import QualityDataModule

DATAMODULES = (CompletionDataModule, QualityDataModule, CanonicalDataModule, BodyDataModule)


def _required(fn) -> list[str]:
    """Names of the parameters of ``fn`` (self left out) that have no default."""
    params = list(inspect.signature(fn).parameters.values())[1:]
    return [p.name for p in params if p.default is p.empty and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)]


@pytest.mark.parametrize("cls", DATAMODULES, ids=lambda c: c.__name__)
def test_datamodule_conforms_to_the_protocol(cls):
    assert issubclass(cls, InspectableDataModule)
    for name in ("prepare_data", "setup", "describe", "show"):
        proto = list(inspect.signature(getattr(InspectableDataModule, name)).parameters)[1:]
        have = list(inspect.signature(getattr(cls, name)).parameters)[1:]
        assert have[:len(proto)] == proto, f"{cls.__name__}.{name}{tuple(have)}: the protocol's parameters are {proto}"
        assert _required(getattr(cls, name)) == _required(getattr(InspectableDataModule, name)), \
            f"{cls.__name__}.{name}: extra parameters need defaults"


def test_protocol_rejects_a_datamodule_without_show():
    class NoShow:
        def prepare_data(self): ...
        def setup(self, stage=None): ...
        def describe(self): return {}

    assert not isinstance(NoShow(), InspectableDataModule)
