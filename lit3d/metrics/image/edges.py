"""Canny edges and the Canny-edge difference of two images.

Grey images ``(B, 1, H, W)`` float (more channels are averaged); edge maps
``(B, 1, H, W) bool``; the difference is ``(B,) float32``.

Why not ``kornia.filters.canny`` itself: it gives the same edge maps (tested, at
most 1e-3 of the pixels differ, from float rounding at threshold ties) but is far
too slow on CPU for the feature table, which runs Canny on 2 x 720 crops per mesh
pair. Measured on 64 grey 200 x 200 renders, 1 thread (kornia 0.9): ours 0.18 s;
``kornia.filters.canny`` 4.3 s (23x; its hysteresis is a loop of dilations until
nothing changes, one pass per pixel of the longest weak chain); kornia with
``hysteresis=False`` plus our connected-component hysteresis 0.52 s (2.8x: its
blur, ``atan2`` and per-direction NMS convolutions). So this module keeps the same
algorithm written as shifted slices and comparisons.
"""
from __future__ import annotations

import math

import torch
import torch.nn.functional as F

from .filters import gaussian_kernel1d, separable_filter


def _blur5(x: torch.Tensor) -> torch.Tensor:
    """5-tap Gaussian (sigma 1) of ``(..., H, W)`` along H and W with reflect border, as shifted slices
    (``kornia.filters.gaussian_blur2d(x, 5, (1, 1), "reflect")`` up to float rounding)."""
    h, w = x.shape[-2:]
    taps = gaussian_kernel1d(5, 1.0)
    if min(h, w) < 3:
        return separable_filter(x, taps, "reflect")
    k = taps.tolist()
    p = F.pad(x, (2, 2, 2, 2), mode="reflect")
    r = torch.add(p[..., 0:h, :], p[..., 4:h + 4, :]).mul_(k[0])
    r.add_(torch.add(p[..., 1:h + 1, :], p[..., 3:h + 3, :]), alpha=k[1]).add_(p[..., 2:h + 2, :], alpha=k[2])
    c = torch.add(r[..., 0:w], r[..., 4:w + 4]).mul_(k[0])
    return c.add_(torch.add(r[..., 1:w + 1], r[..., 3:w + 3]), alpha=k[1]).add_(r[..., 2:w + 2], alpha=k[2])


def canny_edges(img: torch.Tensor, low: float = 0.1, high: float = 0.2, hysteresis: bool = True) -> torch.Tensor:
    """Canny edge map ``(B, 1, H, W) bool`` of grey images ``(B, 1, H, W)``.

    Same algorithm and conventions as ``kornia.filters.canny`` (5x5 Gaussian with
    sigma 1 and reflect border, unnormalised Sobel (as kornia 0.9: thresholds in its units)
    with replicate border, 8-direction
    non-maximum suppression with kornia's tie rule, double threshold, hysteresis
    over 8-neighbours) but several times faster on CPU: blurring and Sobel as shifted
    slices, the direction from comparisons instead of ``atan2``, hysteresis by connected
    components. Agreement with kornia is checked in the tests.
    """
    x = img.float()
    if x.shape[1] != 1:
        x = x.mean(1, keepdim=True)
    x = _blur5(x)
    p = F.pad(x, (1, 1, 1, 1), mode="replicate")
    h, w = x.shape[-2:]

    # separable Sobel: gx = [1 2 1]^T (x) [-1 0 1], gy = [-1 0 1]^T (x) [1 2 1]
    t = torch.add(p[..., 0:h, :], p[..., 2:h + 2, :]).add_(p[..., 1:h + 1, :], alpha=2.0)
    gx = t[..., 2:] - t[..., :-2]
    u = torch.add(p[..., 0:w], p[..., 2:w + 2]).add_(p[..., 1:w + 1], alpha=2.0)
    gy = u[..., 2:, :] - u[..., :-2, :]
    eps = 1e-6
    mag = torch.addcmul(gx * gx, gy, gy).add_(eps).sqrt_()
    mp = F.pad(mag, (1, 1, 1, 1), value=math.sqrt(eps))  # kornia: zero-padded conv of mag

    def nb(dy, dx):
        return mp[..., 1 + dy: 1 + dy + h, 1 + dx: 1 + dx + w]

    # kornia quantises atan2(gy, gx) to 8 directions d = round(angle / 45 deg) mod 8 and
    # compares with the neighbours at offsets d and d + 4; only d = 0, 2 (and their
    # opposites) accept a tie with the first. The line k = d mod 4 follows from comparisons
    # (no atan2): k = 0 within 22.5 deg of the x axis, 2 of the y axis, else 1 / 3 by sign.
    ax, ay = gx.abs(), gy.abs()
    tan22 = math.tan(math.pi / 8)
    m0 = (mag >= nb(0, 1)) & (mag > nb(0, -1))
    m2 = (mag >= nb(1, 0)) & (mag > nb(-1, 0))
    m1 = mag > torch.maximum(nb(1, 1), nb(-1, -1))
    m3 = mag > torch.maximum(nb(1, -1), nb(-1, 1))
    k0 = ay <= tan22 * ax
    k2 = (ax <= tan22 * ay) & ~k0
    diag = ~(k0 | k2)
    same = (gx * gy) > 0
    keep = (k0 & m0) | (k2 & m2) | (diag & ((same & m1) | (~same & m3)))  # bool ops: faster than where
    cand = keep & (mag > max(low, math.sqrt(eps)))
    strong = keep & (mag > max(high, math.sqrt(eps)))
    if not hysteresis:
        return strong | cand
    return _hysteresis(strong, cand)


def _hysteresis(strong: torch.Tensor, cand: torch.Tensor) -> torch.Tensor:
    """Candidates 8-connected (within each image) to a strong pixel: ``(B, 1, H, W) bool``.

    Equal to iterating "a weak pixel with a strong 8-neighbour becomes strong" until
    nothing changes (kornia's loop), done in one connected-component labelling pass
    (``scipy.ndimage.label``) instead of hundreds of dilations.
    """
    import numpy as np
    from scipy import ndimage

    c = cand.detach().cpu().numpy()[:, 0]
    st = strong.detach().cpu().numpy()[:, 0]
    structure = np.zeros((3, 3, 3), bool)
    structure[1] = True  # 8-connectivity inside each image, none across the batch
    lab, n = ndimage.label(c, structure=structure)
    has = np.zeros(n + 1, bool)
    has[lab[st]] = True
    has[0] = False
    return torch.from_numpy(has[lab])[:, None].to(cand.device)


def canny_diff(a: torch.Tensor, b: torch.Tensor, low: float = 0.1, high: float = 0.2) -> torch.Tensor:
    """Canny-edge difference per image ``(B,) float32``: fraction of pixels whose edge labels differ.

    ``a``, ``b``: ``(B, 1, H, W)`` grey images in ``[0, 1]``; ``low``, ``high``: hysteresis
    thresholds on the unnormalised Sobel magnitude (see :func:`canny_edges`).
    """
    ea = canny_edges(a, low, high)
    eb = canny_edges(b, low, high)
    return (ea ^ eb).float().flatten(1).mean(1)
