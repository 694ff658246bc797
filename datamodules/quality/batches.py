"""Rows of a quality feature matrix as a torch Dataset, and the training batch order.

Batches (default collate): ``{"x": (B, F) float32, "y": (B,) float32 in [0, 1],
"shape_id": (B,) int64 index into ``shape_names``, "shape": list[str], "item": list[str]}``.

:class:`ShuffledBatches` draws each training epoch with :func:`lit3d.features.matrix.minibatches`
from one ``np.random.default_rng(seed)``: the batch order ``lit3d.quality.trainer`` trains with,
so the Lightning path and the cross-validation protocol see the same batches for one seed.
"""
from __future__ import annotations

from collections.abc import Iterator, Sequence

import numpy as np
import torch
from torch.utils.data import BatchSampler, Dataset, Sampler

from lit3d.features.matrix import FeatureMatrix, minibatch_count, minibatches


class QualityPairDataset(Dataset):
    """Rows of a :class:`FeatureMatrix` as dicts (module docstring); ``shape_names`` gives the ids."""

    def __init__(self, fm: FeatureMatrix, shape_names: Sequence[str] | None = None):
        self.fm = fm
        self.x = torch.as_tensor(fm.X, dtype=torch.float32)
        self.y = torch.as_tensor(fm.target, dtype=torch.float32)
        ids = {s: i for i, s in enumerate(shape_names if shape_names is not None else fm.shape_names)}
        self.shape_id = torch.as_tensor([ids[str(s)] for s in fm.shapes], dtype=torch.long)

    def __len__(self) -> int:
        return len(self.fm)

    def __getitem__(self, i: int) -> dict:
        return {"x": self.x[i], "y": self.y[i], "shape_id": self.shape_id[i], "shape": str(self.fm.shapes[i]),
                "item": self.fm.items[i]}


class ShuffledBatches(BatchSampler):
    """Epochs of :func:`~lit3d.features.matrix.minibatches` over the indices ``sampler`` yields.

    One generator ``np.random.default_rng(seed)`` is drawn from epoch after epoch (as in
    ``lit3d.quality.trainer``). A last batch of one row joins the previous one (batch norm);
    ``drop_last`` drops a short last batch instead (Lightning passes it when it re-creates the
    sampler around a ``DistributedSampler`` under DDP; ``seed`` is kept then).
    """

    def __init__(self, sampler: Sampler[int] | Sequence[int], batch_size: int, drop_last: bool = False, seed: int = 0):
        super().__init__(sampler, batch_size, drop_last)
        self.seed = int(seed)
        self.rng = np.random.default_rng(self.seed)

    def __iter__(self) -> Iterator[list[int]]:
        index = np.fromiter(iter(self.sampler), dtype=np.int64)
        for batch in minibatches(len(index), self.batch_size, self.rng):
            if self.drop_last and len(batch) < self.batch_size:
                continue
            yield index[batch].tolist()

    def __len__(self) -> int:
        n = len(self.sampler)
        return n // self.batch_size if self.drop_last else minibatch_count(n, self.batch_size)
