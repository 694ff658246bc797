"""Per-sample tensors gathered over an evaluation epoch, correct under DDP.

A protocol that needs every test sample at once (retrieval ranks each item against all the
others) cannot be averaged batch by batch; :class:`GatheredTensors` keeps the batches as list
states reduced by ``"cat"``, so :meth:`~GatheredTensors.compute` returns the samples of every
process (torchmetrics gathers them; uneven shards are fine).

:func:`compute_if_updated` computes any metric only when some process updated it, deciding the
same way on every process (a ``compute()`` that syncs must be reached by all of them).
"""
from __future__ import annotations

import warnings
from collections.abc import Sequence
from typing import Any

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


def compute_if_updated(metric: Metric) -> Any | None:
    """``metric.compute()``, or None when no process updated ``metric`` (nothing is computed).

    The update counts are summed over the processes the metric syncs with (one ``all_reduce``,
    only when its ``compute()`` would sync), so every process takes the same branch: a process
    that saw no batch still joins the others' ``compute()`` and its state gathering, where a
    decision on its own ``update_count`` would leave them waiting. It then computes from the
    other processes' states, so torchmetrics' "compute called before update" warning is
    silenced there; on one process an unused metric is simply skipped (no warning either).
    """
    local = int(metric.update_count)
    total = local
    if metric.sync_on_compute and metric.distributed_available_fn():
        import torch.distributed as dist

        count = torch.tensor([local], dtype=torch.int64, device=metric.device)
        dist.all_reduce(count, op=dist.ReduceOp.SUM, group=metric.process_group)
        total = int(count.item())
    if total == 0:
        return None
    with warnings.catch_warnings():
        if local == 0:
            warnings.filterwarnings("ignore", message=r".*was called before the ``update`` method")
        return metric.compute()
