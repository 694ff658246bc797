"""Dynamic latent code selection of the 3DCascade-GAN generator (thesis 3.2.1, fig. 3.4)."""
from __future__ import annotations

import torch
import torch.nn as nn
import torch.nn.functional as F

SELECTOR_MODES = ("straight_through", "literal")


class LatentSelector(nn.Module):
    """Dynamic latent code selection (thesis 3.2.1, fig. 3.4).

    ``w = sigmoid(FC_n(ReLU(FC_n(l))))``; entries of ``l`` whose ``w`` is among the top ``k`` are
    kept in place, the others are zeroed.

    Modes:
        ``"straight_through"`` (default): forward value ``l * hard``; backward treats the mask as
            ``w``, i.e. ``l * (hard + w - w.detach())``, so the weight net learns.
        ``"literal"``: ``l * hard`` (eq. 3.1 as written; the weight net gets no gradient).

    ``normalize=True`` feeds the weight net ``layer_norm(l)`` (zero mean, unit RMS over the n entries,
    no affine parameters) instead of ``l``: the latent grows during training (RMS 0.05 at
    initialisation to 8-23 after 6 demo epochs), which drives ``FC(ReLU(FC(l)))`` to |z| ~ 100-450,
    where the sigmoid's derivative (1e-8 .. 1e-25) stops every gradient to the weight net. The
    selected values are ``l`` itself either way.

    forward(latent ``l`` (B, n) float) -> (selected (B, n), keep_mask (B, n) float in {0, 1}, k ones per row)
    """

    def __init__(self, n: int, k: int, mode: str = "straight_through", normalize: bool = False):
        super().__init__()
        if mode not in SELECTOR_MODES:
            raise ValueError(f"selector mode '{mode}' unknown; use one of {SELECTOR_MODES}")
        if not 1 <= k <= n:
            raise ValueError(f"selector k={k} must be in [1, n={n}]")
        self.n, self.k, self.mode, self.normalize = n, k, mode, bool(normalize)
        self.weight_net = nn.Sequential(nn.Linear(n, n), nn.ReLU(inplace=True), nn.Linear(n, n), nn.Sigmoid())

    def forward(self, latent: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        w = self.weight_net(F.layer_norm(latent, (self.n,)) if self.normalize else latent)
        idx = torch.topk(w, self.k, dim=1).indices
        hard = torch.zeros_like(w).scatter(1, idx, 1.0)
        if self.mode == "straight_through":
            # = l * (hard + w - w.detach()), written so the forward value is exactly l * hard
            return latent * hard + latent * (w - w.detach()), hard
        return latent * hard, hard

    def extra_repr(self) -> str:
        return f"n={self.n}, k={self.k}, mode={self.mode}, normalize={self.normalize}"
