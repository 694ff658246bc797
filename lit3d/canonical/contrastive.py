"""A contrastive identity term for the canonical task: poses of one subject in a batch pull together,
other subjects push apart (the third identity option, beside the subject classifier and the
phenotype head).

:func:`supervised_contrastive` is the supervised contrastive loss (Khosla et al., 2020, the
"L_out" form): for every anchor with at least one other item of its subject in the batch, minus the
mean log-probability of its positives under a softmax over all other items of the batch, with cosine
similarities divided by a temperature. It names no class set, so it means the same for people never
seen in training (unlike the closed-set classifier).

:class:`ContrastiveEmbedder` says what is compared:

- ``on="latent"``: the MSFE's fused latent ``(B, latent_dim)`` through a two-layer projection (SimCLR's
  head): the code the canonical image is decoded from must tell the people apart;
- ``on="output"``: the predicted canonical form itself (depth times mask, and the mask; ``(B, 2, S, S)``)
  through a small strided CNN: the image that retrieval reads must tell them apart, whatever the pose.

Batches need several poses of each subject (``data.training.batch_poses``, see
:class:`datamodules.canonical.batches.SubjectGroupedBatches`); anchors without a positive in the
batch do not count, and a batch without any gives 0.
"""
from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import nn

CONTRASTIVE_INPUTS = ("latent", "output")


def supervised_contrastive(embeddings: torch.Tensor, labels: torch.Tensor, temperature: float) -> torch.Tensor:
    """Supervised contrastive loss of ``embeddings`` ``(B, D)`` (any scale: L2-normalised here) with
    integer ``labels`` ``(B,)``, at ``temperature`` > 0. Scalar, fp32; 0 (still differentiable) when no
    item has a positive."""
    if temperature <= 0:
        raise ValueError(f"contrastive temperature must be > 0, got {temperature}")
    z = nn.functional.normalize(embeddings.float(), dim=1)
    labels = labels.view(-1).to(z.device)
    n = z.shape[0]
    self_mask = torch.eye(n, dtype=torch.bool, device=z.device)
    logits = (z @ z.t() / temperature).masked_fill(self_mask, float("-inf"))
    log_prob = logits - torch.logsumexp(logits, dim=1, keepdim=True)
    positives = (labels[:, None] == labels[None, :]) & ~self_mask
    n_pos = positives.sum(1)
    anchors = n_pos > 0
    if not bool(anchors.any()):
        return z.sum() * 0.0
    pos_log_prob = log_prob.masked_fill(~positives, 0.0).sum(1)
    return -(pos_log_prob[anchors] / n_pos[anchors]).mean()


class ContrastiveEmbedder(nn.Module):
    """The embedding the contrastive loss compares: from the MSFE latent or from the predicted image."""

    def __init__(self, on: str, latent_dim: int, embed_dim: int, channels: Sequence[int]):
        """``on``: one of :data:`CONTRASTIVE_INPUTS`; ``latent_dim``: the MSFE's fused width (``net.fuser_out``);
        ``embed_dim``: the embedding width; ``channels``: the output CNN's widths, one stride-2 3x3 conv each."""
        super().__init__()
        if on not in CONTRASTIVE_INPUTS:
            raise ValueError(f"task.contrastive.embed must be one of {CONTRASTIVE_INPUTS}, got {on!r}")
        if embed_dim < 1 or (on == "output" and not channels):
            raise ValueError(f"contrastive embedding needs embed_dim >= 1 (and channels for on=output), got "
                             f"embed_dim={embed_dim}, channels={list(channels)}")
        self.on = on
        if on == "latent":
            self.body = nn.Sequential(nn.Linear(latent_dim, latent_dim), nn.ReLU(inplace=True),
                                      nn.Linear(latent_dim, embed_dim))
        else:
            layers: list[nn.Module] = []
            c_in = 2
            for c in channels:
                layers += [nn.Conv2d(c_in, int(c), 3, stride=2, padding=1), nn.ReLU(inplace=True)]
                c_in = int(c)
            layers += [nn.AdaptiveAvgPool2d(1), nn.Flatten(), nn.Linear(c_in, embed_dim)]
            self.body = nn.Sequential(*layers)

    def forward(self, out) -> torch.Tensor:
        """``out``: a :class:`~lit3d.canonical.outputs.CanonicalOutput` (``latent`` ``(B, latent_dim)``;
        ``depth``, ``mask`` ``(B, 1, S, S)``) -> ``(B, embed_dim)``."""
        if self.on == "latent":
            if out.latent is None:
                raise ValueError("task.contrastive.embed=latent needs the MSFE latent (task.net.msfe.use=true)")
            return self.body(out.latent.float())
        mask = out.mask.float()
        return self.body(torch.cat([out.depth.float() * mask, mask], dim=1))
