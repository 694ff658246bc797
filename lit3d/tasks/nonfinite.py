"""NaN/Inf losses: stop with the step and the loss terms named, or skip the step (``task.on_nonfinite``).

Used by the tasks' ``training_step``::

    if not check_losses({"depth": l_depth, "mask": l_mask}, f"step {self.global_step}", mode):
        return None   # "skip": no backward, no optimizer step
"""
from __future__ import annotations

from collections.abc import Mapping

import torch

MODES = ("raise", "skip")


class NonFiniteLossError(FloatingPointError):
    """A loss became NaN/Inf: the message names the step and the loss term(s)."""


def nonfinite_terms(losses: Mapping[str, torch.Tensor]) -> list[str]:
    """Names of the losses that hold a NaN or Inf."""
    return [k for k, v in losses.items() if not bool(torch.isfinite(v.detach()).all())]


def check_losses(losses: Mapping[str, torch.Tensor], where: str, mode: str = "raise") -> bool:
    """True when every loss is finite; else raise :class:`NonFiniteLossError` (``mode="raise"``)
    or return False (``mode="skip"``: the caller skips the step and counts it)."""
    if mode not in MODES:
        raise ValueError(f"task.on_nonfinite must be one of {MODES}, got {mode!r}")
    bad = nonfinite_terms(losses)
    if not bad:
        return True
    if mode == "skip":
        return False
    raise NonFiniteLossError(f"non-finite loss at {where}: {', '.join(bad)} "
                             "(set task.on_nonfinite=skip to skip such steps)")
