"""Pixel errors per image: MSE, RMSE, PSNR and SRE.

Images ``(B, C, H, W)`` float (any shape with a leading batch axis); values ``(B,) float32``.

Why not a library: torchmetrics' ``mean_squared_error`` reduces over the whole
batch (no per-image values) and its ``peak_signal_noise_ratio`` gives ``inf`` for
equal images where we cap at ``PSNR_MAX_DB``; each measure here is one line.
The values are checked against ``skimage.metrics`` and torchmetrics in the tests.
"""
from __future__ import annotations

import torch

PSNR_MAX_DB = 100.0


def mse(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Mean squared error per image ``(B,) float32``."""
    return ((a.float() - b.float()) ** 2).flatten(1).mean(1)


def rmse(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Root mean squared error per image ``(B,) float32``."""
    return mse(a, b).sqrt()


def psnr(a: torch.Tensor, b: torch.Tensor, data_range: float = 1.0, max_db: float = PSNR_MAX_DB) -> torch.Tensor:
    """PSNR in dB per image ``(B,) float32``: ``10 log10(range^2 / MSE)``, capped at ``max_db`` (equal images)."""
    e = mse(a, b)
    return (10.0 * torch.log10(data_range**2 / e.clamp_min(1e-30))).clamp(max=max_db)


def sre(a: torch.Tensor, b: torch.Tensor, max_db: float = PSNR_MAX_DB) -> torch.Tensor:
    """Signal to reconstruction error ratio in dB per image ``(B,) float32``, ``a`` = reference.

    ``SRE = 10 log10(mean(a)^2 / MSE(a, b))`` (Lanaras et al. 2018); capped at
    ``max_db``; an all-black reference with any error gives ``-max_db``.
    """
    e = mse(a, b)
    mu2 = a.float().flatten(1).mean(1) ** 2
    val = 10.0 * torch.log10(mu2.clamp_min(1e-30) / e.clamp_min(1e-30))
    return val.clamp(-max_db, max_db)
