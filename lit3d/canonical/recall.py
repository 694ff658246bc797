"""Closed-set recall: name the subject from the posed depth image, then draw its canonical image.

A diagnostic row, not a canonical-form generator: where every test subject is also a training
subject (TOSCA's classes are single subjects, so any pose split keeps them), a network can score
retrieval by recognising *who* it sees and recalling that subject's canonical image from training,
without modelling the deformation at all. Its retrieval figure is what recognition from one depth
view, learned from the same data, reaches on the same protocol; it cannot canonicalise a subject it
was not trained on (it always answers with one of the training subjects).

Tensors (B = batch, K = subjects, S = image size):
    depth, mask ``(B, 1, S, S)`` float32 -> :class:`~lit3d.canonical.outputs.CanonicalOutput` with
    ``latent`` = subject logits ``(B, K)``; depth and mask are the probability-weighted mix of the
    ``K`` canonical templates ``(K, 1, S, S)`` (depth normalised by the mixed mask, so a confident
    prediction is exactly the template).
"""
from __future__ import annotations

from collections.abc import Sequence

import lightning.pytorch as pl
import torch
import torch.nn as nn

from lit3d.canonical.outputs import CanonicalOutput
from lit3d.utils.data_hooks import HasEvaluationViews

MASK_EPS = 1e-4  # mask probabilities are clamped to [eps, 1 - eps] before the logit


class SubjectRecallNet(nn.Module):
    """``len(channels)`` x [Conv3x3, BatchNorm, ReLU, MaxPool 2] -> global average -> Linear -> K logits.

    The templates (each subject's canonical depth and mask, ``(K, 1, S, S)``) are buffers, so a
    checkpoint carries them; :meth:`set_templates` fills them from the training data before fitting.
    """

    def __init__(self, n_subjects: int, image_size: int, channels: Sequence[int]):
        super().__init__()
        if int(n_subjects) < 2:
            raise ValueError(f"the recall net needs n_subjects >= 2 (got {n_subjects}): set task.identity.classes")
        layers, prev = [], 2
        for ch in channels:
            layers += [nn.Conv2d(prev, ch, 3, padding=1), nn.BatchNorm2d(ch), nn.ReLU(), nn.MaxPool2d(2)]
            prev = ch
        self.features = nn.Sequential(*layers)
        self.classifier = nn.Linear(prev, int(n_subjects))
        size = (int(n_subjects), 1, int(image_size), int(image_size))
        self.register_buffer("template_depth", torch.zeros(size))
        self.register_buffer("template_mask", torch.zeros(size))

    @property
    def n_subjects(self) -> int:
        return self.classifier.out_features

    def set_templates(self, depth: torch.Tensor, mask: torch.Tensor) -> None:
        """Copy each subject's canonical ``depth`` and ``mask`` ``(K, 1, S, S)`` (row k = subject index k)."""
        want = tuple(self.template_depth.shape)
        for name, t in (("depth", depth), ("mask", mask)):
            if tuple(t.shape) != want:
                raise ValueError(f"recall templates: {name} has shape {tuple(t.shape)}, expected {want} "
                                 "(one canonical image per subject, identity.classes subjects, image_size)")
        self.template_depth.copy_(depth)
        self.template_mask.copy_(mask)

    def logits(self, depth: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        """``(B, 1, S, S)`` depth and mask -> subject logits ``(B, K)``."""
        return self.classifier(self.features(torch.cat([depth, mask], 1)).mean((2, 3)))

    def forward(self, depth: torch.Tensor, mask: torch.Tensor) -> CanonicalOutput:
        logits = self.logits(depth, mask)
        p = torch.softmax(logits.float(), 1)
        m = torch.einsum("bk,kchw->bchw", p, self.template_mask)
        d = torch.einsum("bk,kchw->bchw", p, self.template_depth * self.template_mask) / m.clamp_min(MASK_EPS)
        m = m.clamp(MASK_EPS, 1 - MASK_EPS)
        return CanonicalOutput(depth=d.clamp(0, 1), mask=m, mask_logits=torch.logit(m), latent=logits)


class RecallTemplates(pl.Callback):
    """Before fitting, fills a recall module's templates with the training data's canonical images, seen
    from the first evaluation view (the view every test target is drawn in), through the canonical
    DataModule's interface (``views("test")`` and the training dataset's ``canonical_templates(view)``);
    the module (``net.set_templates``) only holds them. Added by the module itself for ``arch=recall``."""

    def on_fit_start(self, trainer: pl.Trainer, pl_module: pl.LightningModule) -> None:
        dm = getattr(trainer, "datamodule", None)
        if not isinstance(dm, HasEvaluationViews):
            raise ValueError("arch=recall fills its templates from a canonical DataModule; fit with datamodule=...")
        depth, mask = dm.datasets["train"].canonical_templates(dm.views("test")[0])
        pl_module.net.set_templates(depth.to(pl_module.device), mask.to(pl_module.device))
