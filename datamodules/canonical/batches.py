"""Training batches made of several poses of each subject (``data.training.batch_poses``): what a contrastive
identity term (:mod:`lit3d.canonical.contrastive`) needs, since a random batch of 16 among 140 people
x 24 poses rarely holds one person twice.
"""
from __future__ import annotations

from collections.abc import Iterator, Sequence

import torch
from torch.utils.data import Sampler

from datamodules.cache import DataError
from datamodules.loaders import distributed_world


class SubjectGroupedBatches(Sampler[list[int]]):
    """Batch sampler: each batch holds ``batch_size // poses`` subjects with ``poses`` items each.

    Every epoch, each subject's items are shuffled and cut into groups of ``poses`` (a last group
    shorter than ``poses`` is dropped for that epoch), the groups of all subjects are shuffled, and
    consecutive groups fill the batches (a last batch with fewer groups is kept, one group at least).
    No item appears twice in an epoch. The order follows ``seed`` and the epoch (each ``__iter__`` is
    the next epoch, or :meth:`set_epoch`). On several processes each rank takes every world-th batch
    (run with ``trainer.use_distributed_sampler=false`` so Lightning keeps this sampler).
    """

    def __init__(self, records: Sequence[dict], batch_size: int, poses: int, seed: int):
        """``records``: the training items' dicts (``"subject"`` read); ``poses`` >= 2 and ``batch_size`` a
        multiple of it; DataError otherwise or when no subject has ``poses`` items."""
        if poses < 2 or batch_size < poses or batch_size % poses:
            raise DataError(f"batch_poses={poses} needs 2 <= batch_poses <= batch_size and batch_size "
                            f"({batch_size}) a multiple of it")
        by_subject: dict[str, list[int]] = {}
        for i, r in enumerate(records):
            by_subject.setdefault(str(r["subject"]), []).append(i)
        if not any(len(v) >= poses for v in by_subject.values()):
            raise DataError(f"batch_poses={poses}: no training subject has that many items "
                            f"(most: {max((len(v) for v in by_subject.values()), default=0)})")
        self.groups_per_batch = batch_size // poses
        self.poses = poses
        self.seed = int(seed)
        self.epoch = 0
        self._by_subject = [torch.tensor(v) for _, v in sorted(by_subject.items())]

    def set_epoch(self, epoch: int) -> None:
        self.epoch = int(epoch)

    def _batches(self) -> list[list[int]]:
        g = torch.Generator().manual_seed(self.seed * 100_003 + self.epoch)
        groups: list[list[int]] = []
        for items in self._by_subject:
            shuffled = items[torch.randperm(len(items), generator=g)].tolist()
            groups += [shuffled[i:i + self.poses] for i in range(0, len(shuffled) - self.poses + 1, self.poses)]
        order = torch.randperm(len(groups), generator=g).tolist()
        groups = [groups[i] for i in order]
        k = self.groups_per_batch
        batches = [sum(groups[i:i + k], []) for i in range(0, len(groups), k)]
        rank, world = distributed_world()
        return batches[rank::world]

    def __iter__(self) -> Iterator[list[int]]:
        batches = self._batches()
        self.epoch += 1
        return iter(batches)

    def __len__(self) -> int:
        groups = sum(len(v) // self.poses for v in self._by_subject)
        n = -(-groups // self.groups_per_batch)
        rank, world = distributed_world()
        return len(range(rank, n, world))
