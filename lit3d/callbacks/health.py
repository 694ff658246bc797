"""Training health: per parameter group gradient norms and update/weight ratios, every N batches.

:class:`TrainingHealth` (in ``conf/callbacks/default.yaml``) works with automatic and manual
optimisation alike: on every ``every_n_batches``-th training batch it copies the weights at
``on_train_batch_start`` and, at ``on_train_batch_end`` (after every optimiser step of the
batch), logs per group to the Lightning loggers (CSV, W&B) at ``trainer.global_step``:

    health/<group>/grad_norm      L2 norm of the group's last gradient (``p.grad`` after the step)
    health/<group>/grad_rms       grad_norm / sqrt(number of elements)
    health/<group>/update_ratio   |w_after - w_before| / |w_before| over the batch's optimiser steps
                                  (GAN: one generator step and ``critic_steps`` critic steps)

A healthy Adam group moves by roughly ``lr`` relative to its weight scale per step (1e-4..1e-2);
a ratio orders of magnitude below its neighbours' means the group does not learn (e.g. gradients
far below Adam's eps). Groups come from the module's ``health_groups() -> {name: [params]}`` when
it has one, else one group per top-level child module with trainable parameters.
"""
from __future__ import annotations

import re

import lightning.pytorch as pl
import torch

from lit3d.utils.task_hooks import HasHealthGroups


def _key(name: str) -> str:
    return re.sub(r"[^0-9A-Za-z_.-]+", "_", name.strip())


def parameter_groups(module: torch.nn.Module) -> dict[str, list[torch.nn.Parameter]]:
    """``module.health_groups()`` if defined, else ``{child name: trainable params}``."""
    if isinstance(module, HasHealthGroups):
        groups = module.health_groups()
    else:
        groups = {name: list(child.parameters()) for name, child in module.named_children()}
    trainable = {_key(k): [p for p in ps if p.requires_grad] for k, ps in groups.items()}
    return {k: ps for k, ps in trainable.items() if ps}


@torch.no_grad()
def group_stats(params: list[torch.nn.Parameter], before: list[torch.Tensor] | None = None) -> dict[str, float]:
    """``grad_norm``, ``grad_rms`` of the params' ``.grad`` (absent grads count as 0) and, given the
    weights ``before`` the step, ``update_ratio = |w - before| / |before|`` (fp64 sums)."""
    n = sum(p.numel() for p in params)
    g2 = sum((p.grad.double().pow(2).sum() for p in params if p.grad is not None), torch.zeros((), dtype=torch.float64))
    out = {"grad_norm": float(g2.sqrt()), "grad_rms": float((g2 / max(n, 1)).sqrt())}
    if before is not None:
        zero = torch.zeros((), dtype=torch.float64)
        d2 = sum(((p.detach().double() - b.double()).pow(2).sum() for p, b in zip(params, before)), zero)
        w2 = sum((b.double().pow(2).sum() for b in before), zero)
        out["update_ratio"] = float(torch.sqrt(d2) / torch.sqrt(w2).clamp_min(1e-30))
    return out


class TrainingHealth(pl.Callback):
    """Log per-group gradient norms and update/weight ratios every ``every_n_batches`` batches.

    Args:
        every_n_batches: measure on training batches 0, N, 2N, ... of the fit (counted here, so it
            does not depend on how many optimiser steps one batch makes).
        prefix: metric name prefix.
    """

    def __init__(self, every_n_batches: int = 50, prefix: str = "health"):
        if every_n_batches < 1:
            raise ValueError(f"every_n_batches={every_n_batches} must be >= 1")
        self.every_n_batches = int(every_n_batches)
        self.prefix = prefix
        self._batches = 0
        self._before: dict[str, list[torch.Tensor]] | None = None
        self.last: dict[str, float] = {}

    def on_train_batch_start(self, trainer: pl.Trainer, pl_module: pl.LightningModule, batch, batch_idx: int) -> None:
        self._before = None
        if self._batches % self.every_n_batches == 0:
            self._before = {k: [p.detach().clone() for p in ps] for k, ps in parameter_groups(pl_module).items()}

    def on_train_batch_end(self, trainer: pl.Trainer, pl_module: pl.LightningModule, outputs, batch, batch_idx: int) -> None:
        self._batches += 1
        if self._before is None:
            return
        metrics: dict[str, float] = {}
        for name, params in parameter_groups(pl_module).items():
            for stat, value in group_stats(params, self._before.get(name)).items():
                metrics[f"{self.prefix}/{name}/{stat}"] = value
        self._before = None
        self.last = metrics
        if trainer.is_global_zero:
            for logger in trainer.loggers:
                logger.log_metrics(metrics, step=trainer.global_step)

    def state_dict(self) -> dict:
        return {"batches": self._batches}

    def load_state_dict(self, state_dict: dict) -> None:
        self._batches = int(state_dict.get("batches", 0))
