"""Per-voxel occupancy prior of shape completion: the mean training target, a baseline that
predicts the same grid for every input ("per-voxel prior" rows of results.md)."""
from __future__ import annotations

import torch
from torch.utils.data import DataLoader, Dataset, Subset


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
