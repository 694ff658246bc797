"""``task.compile_step``: ``torch.compile`` of the completion training step's compute, with an eager fallback.

Compiled (inductor, torch.compile's default mode), one compiled function each:

    critic_objective      critic fakes (generator, no graph) + critic on real and fake + the loss; the gradient
                          penalty inside it runs eager (``critic_penalty`` is ``torch.compiler.disable``d: its
                          ``autograd.grad(create_graph=True)`` and the backward of that gradient are a double
                          backward, which AOTAutograd's compiled graphs do not support), so the critic update is
                          two graphs around the eager penalty; without the penalty (``gp_every > 1``) it is one
    generator_objective   generator + BCE (+ stage BCE) + the critic's adversarial term + the classifier

Their backward passes are compiled too (AOTAutograd); the optimiser steps, the non-finite guard and the logging
stay eager (:meth:`lit3d.completion.module.CompletionTask.training_step`). The ``with_penalty`` and
``adversarial`` flags are guarded: each value used compiles once. A batch of another size (the last one of an
epoch) compiles once more, then shapes are dynamic. The classifier's ``int(seen.sum())`` (which labels are seen)
is a graph break: the generator update is two graphs.

Fallback: where torch.compile cannot run (:func:`compile_unavailable`: TorchDynamo unsupported on this Python,
no Triton for CUDA, no C++ compiler for CPU), or where the first call of a compiled function fails (a backend
error), a warning names the reason and that function runs eager from then on; an error that eager raises too
is raised.

Not done here (a GPU session should measure it): CUDA graphs (``mode="reduce-overhead"``) need static shapes
(``drop_last`` batches of one size), no host synchronisation inside a graph (the classifier's ``int(seen.sum())``
and the non-finite guard's checks sync) and no graph breaks to pay off; the critic update's eager penalty splits
it in any case. Worth timing on a GPU: samples/s at batch 3 and 12 with ``task.compile_step=true`` against
eager, the first (compiling) steps apart, and with ``gp_every`` > 1, where most critic updates are one graph.
"""
from __future__ import annotations

import logging
import os
import shutil
from collections.abc import Callable

import torch

log = logging.getLogger("lit3d.completion")

COMPILED = ("critic_objective", "generator_objective")


def compile_unavailable(device: torch.device) -> str | None:
    """Why ``torch.compile`` (inductor) cannot run on ``device`` here, or None."""
    import torch._dynamo

    if not torch._dynamo.is_dynamo_supported():
        return "TorchDynamo does not support this Python"
    if device.type == "cuda":
        from torch.utils._triton import has_triton

        return None if has_triton() else "no Triton (inductor's GPU code generator)"
    if device.type == "cpu":
        compilers = [os.environ.get("CXX") or "", "g++", "clang++", "c++"]
        return None if any(c and shutil.which(c) for c in compilers) else "no C++ compiler (inductor's CPU back end)"
    return None


class CompiledStep:
    """The task's :data:`COMPILED` functions, compiled (or eager, see the module's docstring).

    ``step(name, *args)`` calls ``task.<name>(*args)`` through its compiled function. ``compile_fn``: the compiler
    (``torch.compile`` when None, looked up at construction).
    """

    def __init__(self, task: torch.nn.Module, compile_fn: Callable | None = None):
        compile_fn = compile_fn or torch.compile
        self.eager = {name: getattr(task, name) for name in COMPILED}
        reason = compile_unavailable(task.device)
        if reason:
            log.warning("task.compile_step: torch.compile is unavailable (%s); the step runs eager", reason)
            self.fns = dict(self.eager)
            self.checked = set(COMPILED)
        else:
            self.fns = {name: compile_fn(fn) for name, fn in self.eager.items()}
            self.checked: set[str] = set()

    def __call__(self, name: str, *args):
        fn = self.fns[name]
        if name in self.checked:
            return fn(*args)
        try:
            out = fn(*args)
        except Exception as exc:  # a backend that cannot compile here: eager from now on (eager raises a real error)
            log.warning("task.compile_step: compiling %s failed (%s: %s); it runs eager", name, type(exc).__name__,
                        str(exc).splitlines()[0][:200] if str(exc) else "")
            self.fns[name] = self.eager[name]
            out = self.eager[name](*args)
        self.checked.add(name)
        return out
