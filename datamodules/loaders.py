"""Evaluation data loaders that count every sample once under DDP.

Lightning gives val/test loaders a ``DistributedSampler`` when it runs on several processes; that
sampler pads the dataset with repeated samples so every rank gets the same number, and the padded
samples then enter the means twice. :func:`evaluation_loader` hands out an unrepeated sampler
instead (ranks may get one sample more or less; the metrics are torchmetrics states summed over
ranks, so they need no equal shards). Lightning keeps a sampler that is already distributed.
"""
from __future__ import annotations

from collections.abc import Callable
from typing import Any

from torch.utils.data import DataLoader, Dataset


def distributed_world() -> tuple[int, int]:
    """``(rank, world_size)`` of the running process group, ``(0, 1)`` without one."""
    import torch.distributed as dist

    if dist.is_available() and dist.is_initialized():
        return dist.get_rank(), dist.get_world_size()
    return 0, 1


def evaluation_loader(dataset: Dataset, batch_size: int, num_workers: int = 0,
                      collate_fn: Callable[[list], Any] | None = None, **kwargs: Any) -> DataLoader:
    """An in-order loader over ``dataset``; on several processes, each rank reads its own
    interleaved share (rank r: items r, r + W, ...) and no item is repeated."""
    rank, world = distributed_world()
    sampler = None
    if world > 1:
        from lightning.pytorch.overrides.distributed import UnrepeatedDistributedSampler

        sampler = UnrepeatedDistributedSampler(dataset, num_replicas=world, rank=rank, shuffle=False)
    return DataLoader(dataset, batch_size=batch_size, shuffle=False, sampler=sampler, num_workers=num_workers,
                      collate_fn=collate_fn, **kwargs)
