"""Per-sample tensors gathered over an evaluation epoch, correct under DDP.

A protocol that needs every test sample at once (retrieval ranks each item against all the
others) cannot be averaged batch by batch; :class:`GatheredTensors` keeps the batches as list
states reduced by ``"cat"``, so :meth:`~GatheredTensors.compute` returns the samples of every
process (torchmetrics gathers them; uneven shards are fine).
"""
from __future__ import annotations

from collections.abc import Sequence

import torch
from torchmetrics import Metric
from torchmetrics.utilities.data import dim_zero_cat


class GatheredTensors(Metric):
    """Named per-sample tensors, concatenated along dim 0 over updates and processes.

    ``GatheredTensors(("depth", "label"))``; ``update(depth=(B, ...) tensor, label=(B,) tensor)``
    (every field, the same ``B``); ``compute() -> {"depth": (N, ...), "label": (N,)}`` with ``N``
    the samples of all updates on all processes (dtypes kept), or ``{}`` before any update.
    """

    full_state_update = False

    def __init__(self, fields: Sequence[str], **kwargs):
        super().__init__(**kwargs)
        self.fields = tuple(fields)
        for name in self.fields:
            self.add_state(name, default=[], dist_reduce_fx="cat")

    def update(self, **tensors: torch.Tensor) -> None:
        if set(tensors) != set(self.fields):
            raise ValueError(f"GatheredTensors.update needs exactly {sorted(self.fields)}, got {sorted(tensors)}")
        sizes = {k: int(torch.as_tensor(v).shape[0]) for k, v in tensors.items()}
        if len(set(sizes.values())) != 1:
            raise ValueError(f"GatheredTensors.update: fields differ in batch size {sizes}")
        for name, value in tensors.items():
            getattr(self, name).append(torch.as_tensor(value, device=self.device).detach())

    def compute(self) -> dict[str, torch.Tensor]:
        states = {name: getattr(self, name) for name in self.fields}
        if any(isinstance(v, list) and not v for v in states.values()):
            return {}
        return {name: dim_zero_cat(v) for name, v in states.items()}
