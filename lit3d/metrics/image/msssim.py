"""Multi-scale SSIM (Wang, Simoncelli & Bovik 2003), with exact shortcuts for shapes on a black canvas.

Images ``(B, C, H, W)`` float in ``[0, data_range]``; values ``(B,) float32``.

Why not ``torchmetrics.functional.image.multiscale_structural_similarity_index_measure``:
its values equal ours (tested, within float32 filtering noise), but it raises for
images under about 176 px a side (ours uses as many scales as fit) and has none of
the shortcuts the feature table needs: ``cs0`` (reuse the scale-0 contrast-structure
already computed for Mask-SSIM), ``box`` / ``crop`` (filter only near the shape and
count the empty background analytically).
"""
from __future__ import annotations

import torch
import torch.nn.functional as F

from .filters import halve, zero_window
from .ssim import ssim_parts

MS_SSIM_WEIGHTS = (0.0448, 0.2856, 0.3001, 0.2363, 0.1333)


def _ms_scales(size: int, weights, window_size: int, device) -> tuple[int, torch.Tensor]:
    """Number of scales that fit an image of side ``size``, and their renormalised weights ``(scales,) float32``."""
    w = torch.tensor(weights, dtype=torch.float32, device=device)
    scales = len(weights)
    while scales > 1 and size < (window_size - 1) * 2 ** (scales - 1) + 1:
        scales -= 1
    return scales, w[:scales] / w[:scales].sum()


def _canvas_means(lum: torch.Tensor, cs: torch.Tensor, outside: float,
                  total: float) -> tuple[torch.Tensor, torch.Tensor]:
    """Canvas means ``(B,)`` of ``l * cs`` and ``cs`` from maps of a window of it; the
    ``outside`` other pixels of the ``total`` see only zeros and have ``l = cs = 1``."""
    return ((lum * cs).flatten(1).sum(1) + outside) / total, (cs.flatten(1).sum(1) + outside) / total


def _boxed_means(x: torch.Tensor, y: torch.Tensor, box, window_size: int, sigma: float, data_range: float,
                 k1: float, k2: float, padding: str) -> tuple[torch.Tensor, torch.Tensor]:
    """Full-canvas means of ``l * cs`` and ``cs`` ``(B,)``, filtering only near ``box``.

    ``box = (y0, y1, x0, x1)`` must contain every non-zero pixel of both images.
    Pixels farther than the window radius from the box see only zeros in both
    images, where ``l = cs = 1`` exactly; they are counted analytically.
    """
    h, w = x.shape[-2:]
    if box is None:
        lum, cs = ssim_parts(x, y, window_size, sigma, data_range, k1, k2, padding)
        return (lum * cs).flatten(1).mean(1), cs.flatten(1).mean(1)
    m = (window_size - 1) // 2 + 1
    y0, y1, x0, x1 = max(box[0] - m, 0), min(box[1] + m, h), max(box[2] - m, 0), min(box[3] + m, w)
    lum, cs = ssim_parts(x[..., y0:y1, x0:x1], y[..., y0:y1, x0:x1], window_size, sigma, data_range, k1, k2,
                         padding)
    total = float(h * w)
    return _canvas_means(lum, cs, total - float((y1 - y0) * (x1 - x0)), total)


def ms_ssim(a: torch.Tensor, b: torch.Tensor, weights=MS_SSIM_WEIGHTS, window_size: int = 11,
            sigma: float = 1.5, data_range: float = 1.0, k1: float = 0.01, k2: float = 0.03,
            padding: str = "valid", cs0: torch.Tensor | None = None, box=None, crop=None) -> torch.Tensor:
    """Multi-scale SSIM per image ``(B,) float32`` (Wang, Simoncelli & Bovik 2003).

    Scale ``j`` contributes ``mean(cs_j) ** w_j`` (``mean(l * cs) ** w`` at the last
    scale), images are halved by 2x2 average pooling between scales. Needs
    ``min(H, W) >= (window_size - 1) * 2 ** (scales - 1) + 1`` (161 px for 5 scales
    with 11-tap windows, about 176 px in torchmetrics' check); smaller images use
    as many scales as fit (weights renormalised). Negative means are clamped at 0
    (no NaN from fractional powers).

    Shortcuts (same result): ``cs0`` is the already known scale-0 mean
    contrast-structure ``(B,)``; ``box = (y0, y1, x0, x1)`` says both images are 0
    outside it (not with ``padding="valid"``), so filtering is done near the box only;
    ``crop = (y0, x0, H, W)`` says ``a``, ``b`` are only the window at ``(y0, x0)`` of
    ``H x W`` canvases that are 0 outside it (the result is that of the full canvases).
    """
    if (box is not None or crop is not None) and padding == "valid":
        raise ValueError("box/crop shortcut needs a same-size padding, not 'valid'")
    if crop is not None:
        return _ms_ssim_crop(a, b, crop, weights, window_size, sigma, data_range, k1, k2, padding, cs0)
    scales, w = _ms_scales(min(a.shape[-2:]), weights, window_size, a.device)
    vals = []
    x, y = a.float(), b.float()
    for j in range(scales):
        bj = None
        if box is not None:
            f = 2**j
            bj = (box[0] // f, -(-box[1] // f), box[2] // f, -(-box[3] // f))
        if j == 0 and cs0 is not None and scales > 1:
            vals.append(cs0)
        else:
            full, cs = _boxed_means(x, y, bj, window_size, sigma, data_range, k1, k2, padding)
            vals.append(full if j == scales - 1 else cs)
        if j < scales - 1:
            x, y = F.avg_pool2d(x, 2), F.avg_pool2d(y, 2)
    v = torch.stack(vals, 1).clamp_min(0.0)
    return torch.prod(v ** w, dim=1)


def _ms_ssim_crop(a, b, crop, weights, window_size, sigma, data_range, k1, k2, padding, cs0):
    """:func:`ms_ssim` ``(B,)`` of canvases given by their non-zero window (see ``crop`` there).

    The crop is halved between scales (zero-padded to an even origin and size, so its
    pixels are the canvas pyramid's); scale ``j`` filters only the crop's footprint
    ``+ radius + 1`` (clipped to the floor-size canvas of that scale); the other
    pixels see only zeros in both images and have ``l = cs = 1`` exactly.
    """
    y0, x0, hh, ww = (int(v) for v in crop)
    scales, wt = _ms_scales(min(hh, ww), weights, window_size, a.device)
    m = (window_size - 1) // 2 + 1
    x, y = a.float(), b.float()
    vals = []
    for j in range(scales):
        if j > 0:  # halve the crop itself, first aligning its origin and size to even
            py, px = y0 % 2, x0 % 2
            h, w = x.shape[-2:]
            pad = (px, (w + px) % 2, py, (h + py) % 2)
            if any(pad):
                x, y = F.pad(x, pad), F.pad(y, pad)
            x, y = halve(x), halve(y)
            y0, x0 = (y0 - py) // 2, (x0 - px) // 2
        if j == 0 and cs0 is not None and scales > 1:
            vals.append(cs0)
            continue
        f = 2**j
        h, w = x.shape[-2:]
        hj, wj = hh // f, ww // f  # floor sizes of repeated halving
        r0, r1 = max(y0 - m, 0), min(y0 + h + m, hj)
        c0, c1 = max(x0 - m, 0), min(x0 + w + m, wj)
        xs = zero_window(x, (y0, x0), (r0, r1), (c0, c1))
        ys = zero_window(y, (y0, x0), (r0, r1), (c0, c1))
        lum, cs = ssim_parts(xs, ys, window_size, sigma, data_range, k1, k2, padding)
        total = float(hj * wj)
        full, cs_mean = _canvas_means(lum, cs, total - float((r1 - r0) * (c1 - c0)), total)
        vals.append(full if j == scales - 1 else cs_mean)
    v = torch.stack(vals, 1).clamp_min(0.0)
    return torch.prod(v**wt, dim=1)
