"""FLOPs and activation memory of one canonical training step, counted on the meta device.

The step of :meth:`lit3d.canonical.module.CanonicalTask.training_step` (automatic optimisation): the
net's forward on the posed depth + mask, the depth/mask loss (:func:`lit3d.canonical.losses.canonical_loss`)
and, with the warp head, its terms (:func:`lit3d.canonical.warp_loss.warp_terms`, on a batch without
flow targets, as ``benchmarks/bench_canonical.py`` times it), then the backward, on meta tensors under
:class:`lit3d.utils.step_cost.CostCounter` and :class:`lit3d.utils.step_cost.SavedBytes`. The identity
head (off in the shipped configs) is refused rather than left out silently.
The optimiser update and element-wise work are not counted.
"""
from __future__ import annotations

import torch

from lit3d.canonical.losses import canonical_loss
from lit3d.canonical.warp_loss import warp_terms
from lit3d.utils.step_cost import CostCounter, SavedBytes

META = torch.device("meta")


def _batch(size: int, batch: int) -> dict:
    """Meta ``depth``, ``mask``, ``canon_depth``, ``canon_mask``: ``(B, 1, S, S)``."""
    t = torch.zeros(batch, 1, size, size, device=META)
    return {"depth": t, "mask": t.clone(), "canon_depth": t.clone(), "canon_mask": t.clone()}


def _measure(task, size: int, batch: int) -> dict:
    hp = task.hparams
    b = _batch(size, batch)
    with CostCounter() as c, SavedBytes() as saved:
        out = task.net(b["depth"], b["mask"])
        loss = canonical_loss(out.depth, out.mask, b["canon_depth"], b["canon_mask"], task.loss_alpha, task.loss_beta,
                              hp.mask_loss, out.mask_logits)["loss"]
        if out.flow is not None:
            warp = warp_terms(out, b)
            loss = loss + sum(getattr(task.warp, f"{k}_weight") * v for k, v in warp.items())
        peak = saved.peak
        loss.backward()
    task.zero_grad(set_to_none=True)
    return {"flops": c.flops, "ops": c.ops, "saved": peak}


def canonical_step_cost(task, size: int) -> dict:
    """``{"flops", "ops", "saved_bytes"}`` of one training step of ``task`` (a
    :class:`~lit3d.canonical.module.CanonicalTask` built on the meta device) on ``size``^2 images, per image
    (FLOPs and saved bytes: the slope between batch 1 and 2; ops: kernel-like aten ops of one step)."""
    if any(p.device.type != "meta" for p in task.parameters()):
        raise ValueError("step cost: build the task on the meta device (with torch.device('meta'): ...)")
    if task.identity.weight > 0:
        raise ValueError("canonical step cost counts the net, depth/mask and warp terms only; identity.weight > 0")
    one, two = _measure(task, size, 1), _measure(task, size, 2)
    return {"flops": two["flops"] - one["flops"], "ops": one["ops"], "saved_bytes": two["saved"] - one["saved"]}
