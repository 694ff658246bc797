"""FSIM, the feature similarity index (Zhang et al. 2011), grey-level, with a crop shortcut.

Images ``(B, C, H, W)`` float in ``[0, data_range]``; values ``(B,) float32``. Two flat
images (no phase congruency anywhere) give 1.

No library in the dependencies provides FSIM (piq does, but is not a dependency;
kornia, torchmetrics, scikit-image do not). ``tests/metrics/test_fsim_piq.py`` checks it against piq's
``fsim(..., chromatic=False)`` on real grey photographs (within 2e-5). The Scharr gradient is written out as
shifted slices: ``kornia.filters.spatial_gradient`` offers only ``sobel`` and
``diff`` kernels, and MATLAB's ``conv2(..., 'same')`` zero border is kept exactly.
"""
from __future__ import annotations

import torch
import torch.nn.functional as F

from .filters import halve, zero_window
from .phase_congruency import phase_congruency

FSIM_CROP_MARGIN = 8  # pixels at FSIM resolution around the foreground crop


def _fsim_region(origin, hw, canvas, f: int, margin: int, multiple: int = 8):
    """FSIM-resolution rows/cols ``[(r0, r1), (c0, c1)]`` covering a crop plus ``margin`` (clipped)."""
    lo = (f - 1) // 2
    out = []
    for o, n, full in zip(origin, hw, canvas):
        size = -(-full // f)
        a0, a1 = max((o + lo) // f - margin, 0), min(-(-(o + n + lo) // f) + margin, size)
        want = min(-(-(a1 - a0) // multiple) * multiple, size)  # round up: fewer filter banks
        a1 = min(a0 + want, size)
        a0 = a1 - want
        out.append((a0, a1))
    return out


def scharr_magnitude(img: torch.Tensor) -> torch.Tensor:
    """Scharr gradient magnitude ``(B, H, W) float32`` of ``(B, H, W)`` images, as FSIM's MATLAB code.

    Kernels ``dx = [3 0 -3; 10 0 -10; 3 0 -3] / 16``, ``dy = dx'`` applied with
    ``conv2(..., 'same')`` (zero border; conv2 flips the kernels).
    """
    gp = F.pad(img[:, None], (1, 1, 1, 1))  # conv2 'same' zero padding
    gx = (3 * (gp[..., :-2, :-2] - gp[..., :-2, 2:]) + 10 * (gp[..., 1:-1, :-2] - gp[..., 1:-1, 2:])
          + 3 * (gp[..., 2:, :-2] - gp[..., 2:, 2:])) / -16.0
    gy = (3 * (gp[..., :-2, :-2] - gp[..., 2:, :-2]) + 10 * (gp[..., :-2, 1:-1] - gp[..., 2:, 1:-1])
          + 3 * (gp[..., :-2, 2:] - gp[..., 2:, 2:])) / -16.0
    return torch.sqrt(gx**2 + gy**2)[:, 0]


def fsim(a: torch.Tensor, b: torch.Tensor, data_range: float = 1.0, downsample: int | None = None,
         crop=None, margin: int = FSIM_CROP_MARGIN) -> torch.Tensor:
    """Grey-level FSIM per image ``(B,) float32`` (Zhang et al. 2011), our own torch implementation.

    Follows the authors' MATLAB ``FeatureSIM``: images scaled to 0..255, averaged and
    subsampled by ``F = max(1, round(min(H, W) / 256))`` (or ``downsample``), phase
    congruency from a 4-scale x 4-orientation log-Gabor bank, Scharr gradients,
    ``T1 = 0.85``, ``T2 = 160``. Channels are averaged to grey first. Two flat
    images (no phase congruency anywhere) give 1.

    ``crop = (y0, x0, H, W)``: ``a``, ``b`` are the window at ``(y0, x0)`` of ``H x W``
    canvases that are 0 outside it (rendered views on a black background). Then FSIM
    is computed on the window's footprint at FSIM resolution plus ``margin`` pixels
    (rounded up to a multiple of 8, clipped to the canvas) — an approximation of the
    full-canvas value: the log-Gabor responses are those of the (periodic) crop, phase
    congruency outside it counts as 0 (far from the shape the responses are tiny and
    their PC ratio is noise; the full-canvas value drifts with the amount of empty
    background, like plain SSIM), and the noise threshold uses the full canvas's
    median (see :func:`phase_congruency`). The subsampling and gradients are exact.
    """
    f = None if downsample is None else int(downsample)
    if crop is None:
        h, w = a.shape[-2:]
        origin, canvas = (0, 0), (h, w)
    else:
        origin, canvas = (int(crop[0]), int(crop[1])), (int(crop[2]), int(crop[3]))
    if f is None:
        f = max(1, round(min(canvas) / 256))
    x = a.float().mean(1, keepdim=True) * (255.0 / data_range)
    y = b.float().mean(1, keepdim=True) * (255.0 / data_range)
    full_pixels = None
    if crop is not None or f > 1:
        # MATLAB: conv2(Y, ones(F)/F^2, 'same') then Y(1:F:end, 1:F:end) = F x F block means
        # of rows/cols starting at i F - (F - 1) // 2 (zero outside the canvas)
        rows, cols = _fsim_region(origin, x.shape[-2:], canvas, f, margin if crop is not None else 10**9)
        lo = (f - 1) // 2
        rr, cc = (rows[0] * f - lo, rows[1] * f - lo), (cols[0] * f - lo, cols[1] * f - lo)
        x, y = zero_window(x, origin, rr, cc), zero_window(y, origin, rr, cc)
        if f == 2:
            x, y = halve(x), halve(y)
        elif f > 2:
            x, y = F.avg_pool2d(x, f), F.avg_pool2d(y, f)
        if crop is not None:
            full_pixels = (-(-canvas[0] // f)) * (-(-canvas[1] // f))
    x, y = x[:, 0], y[:, 0]
    pc = phase_congruency(torch.cat([x, y]), full_pixels=full_pixels)
    pc1, pc2 = pc.chunk(2)
    g1, g2 = scharr_magnitude(torch.cat([x, y])).chunk(2)
    t1, t2 = 0.85, 160.0
    pc_sim = (2 * pc1 * pc2 + t1) / (pc1**2 + pc2**2 + t1)
    g_sim = (2 * g1 * g2 + t2) / (g1**2 + g2**2 + t2)
    pcm = torch.maximum(pc1, pc2)
    num = (g_sim * pc_sim * pcm).flatten(1).sum(1)
    den = pcm.flatten(1).sum(1)
    return torch.where(den > 1e-8, num / den.clamp_min(1e-8), torch.ones_like(den))

