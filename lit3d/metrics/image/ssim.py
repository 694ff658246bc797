"""SSIM (Wang et al. 2004): per-pixel map, its luminance / contrast-structure parts, per-image mean.

Images are ``(B, C, H, W)`` float tensors in ``[0, data_range]``; maps keep that
shape (``H - window + 1`` with ``padding="valid"``), per-image values are ``(B,) float32``.

Why not a library SSIM: ``kornia.metrics.ssim`` does return the per-pixel map that
Mask-SSIM needs, and equals ours with ``padding="reflect"`` (tested), but it only
pads by torch ``reflect``, not scikit-image's ``symmetric`` border that the features
use, and it does not return the luminance and contrast-structure terms separately
(MS-SSIM and the feature table's scale-0 shortcut need ``cs``). torchmetrics'
``structural_similarity_index_measure`` crops the border of its map instead.
"""
from __future__ import annotations

import torch

from .filters import gaussian_kernel1d, separable_filter


def ssim_parts(a: torch.Tensor, b: torch.Tensor, window_size: int = 11, sigma: float = 1.5,
               data_range: float = 1.0, k1: float = 0.01, k2: float = 0.03,
               padding: str = "symmetric") -> tuple[torch.Tensor, torch.Tensor]:
    """Luminance term ``l`` and contrast-structure term ``cs`` maps, each ``(B, C, H, W) float32`` (SSIM = l * cs).

    Gaussian window (``window_size`` taps, ``sigma``), population covariances;
    ``padding`` as in :func:`lit3d.metrics.image.filters.filter_matrix`.
    """
    if a.shape != b.shape:
        raise ValueError(f"image shapes differ: {tuple(a.shape)} vs {tuple(b.shape)}")
    a = a.float()
    b = b.float()
    taps = gaussian_kernel1d(window_size, sigma)
    c1 = (k1 * data_range) ** 2
    c2 = (k2 * data_range) ** 2
    stats = separable_filter(torch.stack([a, b, a * a, b * b, a * b]), taps, padding)
    mu_a, mu_b, aa, bb, ab = stats.unbind(0)
    mu_aa, mu_bb, mu_ab = mu_a * mu_a, mu_b * mu_b, mu_a * mu_b
    var_a = aa - mu_aa
    var_b = bb - mu_bb
    cov = ab - mu_ab
    lum = (2.0 * mu_ab + c1) / (mu_aa + mu_bb + c1)
    cs = (2.0 * cov + c2) / (var_a + var_b + c2)
    return lum, cs


def ssim_map(a: torch.Tensor, b: torch.Tensor, window_size: int = 11, sigma: float = 1.5,
             data_range: float = 1.0, k1: float = 0.01, k2: float = 0.03,
             padding: str = "symmetric") -> torch.Tensor:
    """Per-pixel SSIM map ``(B, C, H, W) float32`` (``H - window + 1`` with ``padding="valid"``).

    Gaussian window (``window_size`` taps, ``sigma``), population covariances
    (Wang et al. 2004). ``padding="reflect"`` equals ``kornia.metrics.ssim``;
    ``"symmetric"`` equals scikit-image's full SSIM map.
    """
    lum, cs = ssim_parts(a, b, window_size, sigma, data_range, k1, k2, padding)
    return lum * cs


def ssim(a: torch.Tensor, b: torch.Tensor, **kw) -> torch.Tensor:
    """Plain (unmasked) SSIM per image ``(B,) float32``: mean of :func:`ssim_map` over C, H, W."""
    return ssim_map(a, b, **kw).flatten(1).mean(1)
