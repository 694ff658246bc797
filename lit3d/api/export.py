"""TorchScript export of the completion generator and the canonical net (``torch.jit.trace``).

    path = export(lit3d.load("completion.ckpt"), "generator.pt")
    net = torch.jit.load(path)                  # no lit3d needed to run it
    probs = net(partial)                        # (B, 1, r, r, r) float32 -> (B, 1, R, R, R) probabilities

What is exported (eval mode; the trace fixes the image / grid size, not the batch size):

- completion: ``(B, 1, r, r, r) float32`` partial grid (0/1, in the training grids' frame) ->
  ``(B, 1, R, R, R) float32`` occupancy probabilities (the generator's last stage, sigmoid);
  occupied = above the checkpoint's threshold (``Completer.threshold``);
- canonical: ``(B, 1, S, S) float32`` normalised depth and mask -> ``(depth, mask)``, both
  ``(B, 1, S, S) float32``: canonical depth in [0, 1] and mask probability.

The output is checked before anything is traced (:func:`check_export_path`): it must not be the
model's own checkpoint, nor any other checkpoint (a ``torch.save`` archive), nor a folder; the file is
written through a temp file and a rename, so it is whole or not there.

ONNX is not offered: the ``onnx`` package is not a dependency.
"""
from __future__ import annotations

import io
import warnings
from pathlib import Path

import torch
from torch import nn

from lit3d.api.checkpoints import Model
from lit3d.reconstruct.canonical import CanonicalMapper
from lit3d.reconstruct.depth_io import InputError
from lit3d.reconstruct.pipeline import Completer
from lit3d.utils.checkpoints import is_checkpoint
from lit3d.utils.io import OutputError, atomic_write_bytes, check_targets, output_error


class CompletionProbabilities(nn.Module):
    """The completion generator as ``(B, 1, r, r, r) -> (B, 1, R, R, R)`` probabilities
    (= :meth:`lit3d.completion.module.CompletionTask.forward`, without the LightningModule)."""

    def __init__(self, generator: nn.Module):
        super().__init__()
        self.generator = generator

    def forward(self, partial: torch.Tensor) -> torch.Tensor:
        return torch.sigmoid(self.generator(partial).logits.float())


class CanonicalDepthMask(nn.Module):
    """The canonical net as ``(depth, mask) (B, 1, S, S) -> (depth, mask probability)``."""

    def __init__(self, net: nn.Module):
        super().__init__()
        self.net = net

    def forward(self, depth: torch.Tensor, mask: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        out = self.net(depth, mask)
        return out.depth, out.mask


def exportable(model: Model, batch: int = 1, seed: int = 0) -> tuple[nn.Module, tuple[torch.Tensor, ...]]:
    """The eval-mode module that :func:`export` traces and random inputs of its sizes on the model's
    device (a 0/1 grid; a depth image in [0.1, 1] inside a random mask)."""
    g = torch.Generator().manual_seed(seed)
    if isinstance(model, Completer):
        r = model.geometry.input_res
        grid = (torch.rand(batch, 1, r, r, r, generator=g) > 0.7).float()
        return CompletionProbabilities(model.task.generator).eval(), (grid.to(model.device),)
    if isinstance(model, CanonicalMapper):
        s = model.image_size
        mask = (torch.rand(batch, 1, s, s, generator=g) > 0.5).float()
        depth = (0.1 + 0.9 * torch.rand(batch, 1, s, s, generator=g)) * mask
        return CanonicalDepthMask(model.task.net).eval(), (depth.to(model.device), mask.to(model.device))
    raise InputError(f"export: needs a completion or canonical model (lit3d.load), got {type(model).__name__}")


def check_export_path(path: str | Path, checkpoint: str | Path | None = None) -> Path:
    """Refuse (:class:`lit3d.utils.io.OutputError`, one line naming the file) an export path that is
    ``checkpoint`` (the model's own, also through a link), any existing checkpoint
    (:func:`lit3d.utils.checkpoints.is_checkpoint`), or a folder; an earlier TorchScript export may be
    replaced. Uses the output check of ``lit3d-reconstruct`` (:func:`lit3d.utils.io.check_targets`)."""
    p = Path(path)
    check_targets([p], [checkpoint] if checkpoint else [], hint="choose another output file")
    if is_checkpoint(p):
        raise OutputError(f"{p}: is a checkpoint (a torch.save archive); export writes TorchScript and never "
                          "replaces a checkpoint: choose another output file")
    return p


def export(model: Model, path: str | Path) -> Path:
    """Trace the net of ``model`` (:func:`lit3d.load` of a completion or canonical checkpoint) to
    TorchScript and save it at ``path`` (a temp file, then a rename); load it with ``torch.jit.load``.
    Returns ``path``. Refused before tracing (:func:`check_export_path`): ``path`` is the model's own
    checkpoint or another checkpoint, or a folder."""
    module, inputs = exportable(model)
    check_export_path(path, getattr(model, "path", None))
    with torch.no_grad(), warnings.catch_warnings():
        # the canonical net compares image sizes (lit3d.canonical.nets.resize_to): fixed by the trace
        # by design; outputs on other inputs and batch sizes are checked in tests/api/test_api.py
        warnings.filterwarnings("ignore", category=torch.jit.TracerWarning, module=r"lit3d\.canonical\.")
        traced = torch.jit.trace(module, inputs, check_trace=False)
    buf = io.BytesIO()
    torch.jit.save(traced, buf)
    try:
        return atomic_write_bytes(path, buf.getvalue())
    except OSError as exc:
        raise output_error(path, exc) from None

