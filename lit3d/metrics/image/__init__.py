"""Image measures for rendered views: SSIM family, FSIM, MSE/RMSE/PSNR, Canny difference, SRE.

All functions are batched torch and run on CPU or GPU. Images are
``(B, C, H, W)`` float tensors in ``[0, data_range]`` (the quality features use
grey ``C = 1`` images in ``[0, 1]``); masks are ``(B, 1, H, W)`` bool or {0, 1}.
Every per-image measure returns ``(B,) float32``.

One module per measure family:

- :mod:`.filters`: banded-matrix Gaussian filtering (scikit-image's and kornia's borders), pooling;
- :mod:`.ssim`: SSIM map and its luminance / contrast-structure parts;
- :mod:`.mask_ssim`: the four Mask-SSIM variants;
- :mod:`.msssim`: MS-SSIM with exact black-canvas shortcuts;
- :mod:`.phase_congruency` and :mod:`.fsim`: FSIM;
- :mod:`.pixel`: MSE, RMSE, PSNR, SRE;
- :mod:`.edges`: Canny edges and their difference;
- :mod:`.color`: BT.601 grey.

The per-pixel SSIM map equals ``kornia.metrics.ssim(a, b, 11)`` with
``padding="reflect"`` and ``skimage.metrics.structural_similarity(...,
gaussian_weights=True, sigma=1.5, use_sample_covariance=False, full=True)`` with
the default ``padding="symmetric"`` (both checked in the tests). Each module says
which library routine it uses, or why it does not.

Degenerate inputs never give NaN: Mask-SSIM of two empty masks is 1 (two equal
empty renders), with no overlap it is 0 (``negative`` variant: -1); FSIM of two
flat images is 1; PSNR is capped at 100 dB.
"""
from __future__ import annotations

from .color import to_grey
from .edges import canny_diff, canny_edges
from .filters import (
    filter_matrix,
    gaussian_kernel1d,
    halve,
    separable_filter,
    zero_window,
)
from .fsim import FSIM_CROP_MARGIN, fsim
from .mask_ssim import MASK_SSIM_VARIANTS, erode3x3, mask_ssim, mask_ssim_all
from .msssim import MS_SSIM_WEIGHTS, ms_ssim
from .phase_congruency import phase_congruency
from .pixel import PSNR_MAX_DB, mse, psnr, rmse, sre
from .ssim import ssim, ssim_map, ssim_parts


__all__ = [
    "FSIM_CROP_MARGIN", "MASK_SSIM_VARIANTS", "MS_SSIM_WEIGHTS", "PSNR_MAX_DB",
    "canny_diff", "canny_edges", "erode3x3", "filter_matrix", "fsim", "gaussian_kernel1d", "halve",
    "mask_ssim", "mask_ssim_all", "ms_ssim", "mse", "phase_congruency", "psnr", "rmse",
    "separable_filter", "sre", "ssim", "ssim_map", "ssim_parts", "to_grey", "zero_window",
]
