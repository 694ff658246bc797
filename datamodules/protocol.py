"""The interface every lit3d DataModule declares beyond Lightning's hooks.

``lit3d-data`` prepares a dataset, prints :meth:`InspectableDataModule.describe` and writes
:meth:`InspectableDataModule.show`'s PNG; the three DataModules
(:class:`~datamodules.completion.CompletionDataModule`,
:class:`~datamodules.quality.QualityDataModule`, :class:`~datamodules.canonical.CanonicalDataModule`)
conform (``tests/datamodules/test_datamodule_protocol.py`` checks it), and a new task's DataModule must too
(docs/CONTRIBUTING_TASKS.md).
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Protocol, runtime_checkable


@runtime_checkable
class InspectableDataModule(Protocol):
    """A DataModule that prepares a cache once and can say and show what it holds.

    - ``prepare_data()``: generate or convert the data into ``data_dir`` (once; through
      :meth:`datamodules.cache.CacheBuilder.prepare_once`);
    - ``setup(stage)``: read the prepared cache into the splits;
    - ``describe() -> dict``: plain values (JSON-ready): counts per split, sizes,
      ``manifest_hash`` and ``config_hash`` of the cache, ``skipped_bad_files``;
    - ``show(n, path) -> Path``: a PNG of ``n`` samples written to ``path`` (more keyword
      arguments, with defaults, are allowed).
    """

    def prepare_data(self) -> None: ...

    def setup(self, stage: str | None = None) -> None: ...

    def describe(self) -> dict[str, Any]: ...

    def show(self, n: int, path: str | Path) -> Path: ...
