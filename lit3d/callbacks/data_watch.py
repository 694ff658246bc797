"""Stop a run whose prepared data changed under it (``conf/callbacks/default.yaml``: ``data_watch``).

Another process can re-prepare a ``data_dir`` while a training reads it (``lit3d-data ... --rebuild``).
The items keep their names, so without a check the run would go on with another config's items.
:class:`DataWatch` asks :func:`datamodules.cache.check_unchanged` about every cache this process
read after the callback was made: at each epoch start (train, validation, test: the manifest and
every item's size) and before every ``every_n_batches``-th training batch (one ``stat`` of the
manifest). A change stops the run with one line (``DataError``, exit 2) naming the folder.
"""
from __future__ import annotations

import time

import lightning.pytorch as pl

from datamodules.cache import check_unchanged


class DataWatch(pl.Callback):
    """Raise :class:`~datamodules.cache.DataError` when the prepared data of this run changed on disk.

    Args:
        every_n_batches: check the manifest before every N-th training batch (0: epoch starts only).
    """

    def __init__(self, every_n_batches: int = 1):
        if every_n_batches < 0:
            raise ValueError(f"every_n_batches must be >= 0, got {every_n_batches}")
        self.every_n_batches = int(every_n_batches)
        self._since = time.monotonic()  # caches read before this callback belong to someone else

    def on_train_epoch_start(self, trainer, pl_module) -> None:
        check_unchanged(self._since, items=True)

    def on_validation_epoch_start(self, trainer, pl_module) -> None:
        check_unchanged(self._since, items=True)

    def on_test_epoch_start(self, trainer, pl_module) -> None:
        check_unchanged(self._since, items=True)

    def on_train_batch_start(self, trainer, pl_module, batch, batch_idx: int) -> None:
        n = self.every_n_batches
        if n and batch_idx % n == 0:
            check_unchanged(self._since, items=False)
