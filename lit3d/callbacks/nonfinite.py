"""NaN/Inf losses: stop with the step and the loss terms named, or skip the step (``task.on_nonfinite``).

Used by the tasks' ``training_step``::

    if not guard_step(self, {"depth": l_depth, "mask": l_mask}, f"step {self.global_step}", mode):
        return None   # "skip": no backward, no optimizer step (counted in self.skipped_steps)
"""
from __future__ import annotations

from collections.abc import Mapping

import torch

MODES = ("raise", "skip")


class NonFiniteLossError(FloatingPointError):
    """A loss became NaN/Inf: the message names the step and the loss term(s)."""


def validate_mode(mode: str) -> None:
    """Raise ValueError unless ``mode`` is one of :data:`MODES` (checked when a task is built)."""
    if mode not in MODES:
        raise ValueError(f"task.on_nonfinite must be one of {MODES}, got {mode!r}")


def nonfinite_terms(losses: Mapping[str, torch.Tensor]) -> list[str]:
    """Names of the losses that hold a NaN or Inf."""
    return [k for k, v in losses.items() if not bool(torch.isfinite(v.detach()).all())]


def check_losses(losses: Mapping[str, torch.Tensor], where: str, mode: str = "raise") -> bool:
    """True when every loss is finite; else raise :class:`NonFiniteLossError` (``mode="raise"``)
    or return False (``mode="skip"``: the caller skips the step and counts it)."""
    validate_mode(mode)
    bad = nonfinite_terms(losses)
    if not bad:
        return True
    if mode == "skip":
        return False
    raise NonFiniteLossError(f"non-finite loss at {where}: {', '.join(bad)} "
                             "(set task.on_nonfinite=skip to skip such steps)")


def guard_step(module, losses: Mapping[str, torch.Tensor], where: str, mode: str = "raise") -> bool:
    """:func:`check_losses` for a task: on a skipped step, count it in ``module.skipped_steps``
    and print one warning naming the step and the terms. True: train on."""
    if check_losses(losses, where, mode):
        return True
    module.skipped_steps += 1
    module.print(f"warning: non-finite loss at {where}: {', '.join(nonfinite_terms(losses))}; "
                 f"step skipped ({module.skipped_steps} so far)")
    return False
