"""Per-voxel occupancy prior of shape completion: the mean training target, a baseline that
predicts the same grid for every input ("per-voxel prior" rows of results.md).

:class:`OccupancyPrior` is the callback that computes it from the DataModule's training split and hands
it to the module (``set_prior``), so the module never reads the training data itself.
"""
from __future__ import annotations

import logging

import lightning.pytorch as pl
import torch
from torch.utils.data import DataLoader, Dataset, Subset

log = logging.getLogger("lit3d.completion")


def mean_training_target(dataset: Dataset, n_items: int, batch_size: int = 8,
                         num_workers: int = 0) -> tuple[torch.Tensor | None, int]:
    """Mean of the ``target`` grids of items ``0 .. n - 1`` of ``dataset``, n = min(n_items, len).

    Index order, no shuffling: every rank and every run averages the same items. Consumes no
    global random numbers (the DataLoader draws its base seed from a private generator), so
    computing the prior does not move the training's random stream.

    Args:
        dataset: map-style; ``dataset[i]["target"]`` is (1, R, R, R) float32 in {0, 1}.
        n_items: how many items to average at most.
        batch_size, num_workers: loading only (the sum of 0/1 grids is exact in float32).

    Returns:
        (prior (1, 1, R, R, R) float32 in [0, 1], number of items averaged), or (None, 0) when
        there is nothing to average.
    """
    n = min(int(n_items), len(dataset))
    if n <= 0:
        return None, 0
    loader = DataLoader(Subset(dataset, range(n)), batch_size=max(int(batch_size), 1), shuffle=False,
                        num_workers=num_workers, generator=torch.Generator())
    total = None
    for batch in loader:
        summed = batch["target"].float().sum(0, keepdim=True)
        total = summed if total is None else total + summed
    return total / n, n


class OccupancyPrior(pl.Callback):
    """Fills the module's ``prior`` from the training data when it has none (``prior_items`` 0): before
    fitting (a resumed fit has it from its checkpoint), and before validating or testing a checkpoint saved
    before the prior was kept. Reads ``trainer.datamodule.train_dataloader()`` (its dataset, batch size and
    workers); the module's ``set_prior(prior, n)`` keeps the result.

    Args:
        n_items: how many training targets to average at most (``task.prior_samples``).
    """

    def __init__(self, n_items: int):
        self.n_items = int(n_items)

    def _fill(self, trainer: pl.Trainer, module: pl.LightningModule, evaluating: bool) -> None:
        if int(module.prior_items) > 0:
            return
        if evaluating:
            log.info("no occupancy prior in this model: averaging up to %d training targets", self.n_items)
        dm = getattr(trainer, "datamodule", None)
        prior, n = None, 0
        if dm is not None:
            loader = dm.train_dataloader()
            prior, n = mean_training_target(loader.dataset, self.n_items, loader.batch_size or 1, loader.num_workers)
        module.set_prior(None if prior is None else prior.to(module.prior.device), n)

    def on_fit_start(self, trainer: pl.Trainer, pl_module: pl.LightningModule) -> None:
        self._fill(trainer, pl_module, evaluating=False)

    def on_validation_start(self, trainer: pl.Trainer, pl_module: pl.LightningModule) -> None:
        self._fill(trainer, pl_module, evaluating=True)

    def on_test_start(self, trainer: pl.Trainer, pl_module: pl.LightningModule) -> None:
        self._fill(trainer, pl_module, evaluating=True)
