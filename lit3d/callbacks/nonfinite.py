"""NaN/Inf losses: stop with the step and the loss terms named, or skip the step (``task.on_nonfinite``).

Used by the tasks' ``training_step``::

    if not guard_step(self, {"depth": l_depth, "mask": l_mask}, f"step {self.global_step}", mode):
        return None   # "skip": no backward, no optimizer step (counted in self.skipped_steps)
"""
from __future__ import annotations

from collections.abc import Mapping

import torch

from lit3d.utils.errors import Lit3dError

MODES = ("raise", "skip")


class NonFiniteLossError(Lit3dError, FloatingPointError):
    """A loss became NaN/Inf: the message names the step and the loss term(s)."""


def validate_mode(mode: str) -> None:
    """Raise ValueError unless ``mode`` is one of :data:`MODES` (checked when a task is built)."""
    if mode not in MODES:
        raise ValueError(f"task.on_nonfinite must be one of {MODES}, got {mode!r}")


def nonfinite_terms(losses: Mapping[str, torch.Tensor]) -> list[str]:
    """Names of the losses that hold a NaN or Inf."""
    return [k for k, v in losses.items() if not bool(torch.isfinite(v.detach()).all())]


def any_rank(flag: bool, device: torch.device | str = "cpu") -> bool:
    """``flag`` OR-ed over every process of an initialised ``torch.distributed`` group (one
    ``all_reduce``; the flag itself when not distributed). ``device``: where the collective's
    tensor lives (CPU for gloo, the GPU for NCCL)."""
    import torch.distributed as dist

    if not (dist.is_available() and dist.is_initialized()) or dist.get_world_size() < 2:
        return flag
    t = torch.tensor([1.0 if flag else 0.0], device=device)
    dist.all_reduce(t, op=dist.ReduceOp.MAX)
    return bool(t.item() > 0)


def check_losses(losses: Mapping[str, torch.Tensor], where: str, mode: str = "raise") -> bool:
    """True when every loss is finite on every process; else raise :class:`NonFiniteLossError`
    (``mode="raise"``) or return False (``mode="skip"``: the caller skips the step and counts it).

    Under DDP the decision is taken jointly (:func:`any_rank`): a NaN on one rank makes every
    rank skip (or raise) the same step, so no rank waits in a gradient all-reduce that the
    others never reach."""
    validate_mode(mode)
    bad = nonfinite_terms(losses)
    device = next(iter(losses.values())).device if losses else "cpu"
    if not any_rank(bool(bad), device):
        return True
    if mode == "skip":
        return False
    raise NonFiniteLossError(f"non-finite loss at {where}: {', '.join(bad) or 'on another process'} "
                             "(set task.on_nonfinite=skip to skip such steps)")


def guard_step(module, losses: Mapping[str, torch.Tensor], where: str, mode: str = "raise") -> bool:
    """:func:`check_losses` for a task: on a skipped step, count it in ``module.skipped_steps``
    and print one warning naming the step and the terms. True: train on."""
    if check_losses(losses, where, mode):
        return True
    module.skipped_steps += 1
    module.print(f"warning: non-finite loss at {where}: {', '.join(nonfinite_terms(losses)) or 'on another process'}; "
                 f"step skipped ({module.skipped_steps} so far)")
    return False
