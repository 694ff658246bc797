"""The optional interfaces a DataModule may offer beyond :class:`datamodules.protocol.InspectableDataModule`,
declared once as :class:`typing.Protocol`\\ s, so that task rooms, callbacks and provenance ask
``isinstance(datamodule, Protocol)`` instead of probing for names (``tests/utils/test_task_hooks.py`` checks
which DataModule offers which, and that no reader probes by name):

- :class:`HasManifest`: ``manifest``, the prepared cache's manifest (``manifest_hash``, ``config_hash``),
  read by run provenance;
- :class:`HasLabelCategories`: ``label_categories`` (the class labels, in order) and ``user_categories``
  (categories of the user's own meshes), read by the completion task's classifier and metrics;
- :class:`NamesItsSource`: ``source_kind`` (``synth``, ``tosca``, ``anny`` ...), read by the canonical report;
- :class:`HasEvaluationViews`: ``views(split) -> [view ids]``, read by the canonical recall templates;
- :class:`ListsHeldOut`: ``held_out_ids() -> [subject ids]`` (the fold's held-out subjects), read by the
  canonical pooled protocol;
- :class:`RendersTurnedCanonical`: ``canonical_turned(subject, view, turn_deg) -> (depth, mask)``, read by
  the canonical retrieval ceiling;
- :class:`GivesMeshes`: ``normalized_mesh(subject, pose) -> (vertices, faces)``, read by the canonical
  mesh baselines.
"""
from __future__ import annotations

from typing import Any, Protocol, runtime_checkable


@runtime_checkable
class HasManifest(Protocol):
    manifest: Any


@runtime_checkable
class HasLabelCategories(Protocol):
    label_categories: Any
    user_categories: Any


@runtime_checkable
class NamesItsSource(Protocol):
    source_kind: Any


@runtime_checkable
class HasEvaluationViews(Protocol):
    def views(self, split: str) -> list[int]: ...


@runtime_checkable
class ListsHeldOut(Protocol):
    def held_out_ids(self) -> list[str]: ...


@runtime_checkable
class RendersTurnedCanonical(Protocol):
    def canonical_turned(self, subject: str, view: int, turn_deg: float) -> Any: ...


@runtime_checkable
class GivesMeshes(Protocol):
    def normalized_mesh(self, subject: str, pose: Any) -> Any: ...
