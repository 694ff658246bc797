"""Colour full-reference measures of rendered views: CIEDE2000 inside masks, and piq's colour measures.

Shapes: images ``a`` (reference) and ``b`` (distorted) are ``(N, 3, H, W)`` float sRGB in ``[0, 1]``
(black background outside the shape); masks ``(N, 1, H, W)`` (or ``(1, 1, H, W)``, shared by the
batch) bool foreground. Every per-image measure is ``(N,) float32``.

- :func:`ciede2000`: mean CIEDE2000 colour difference ΔE00 over the union of the two masks, in
  torch (:func:`delta_e_ciede2000` is the per-pixel formula, Sharma, Wu & Dalal 2005). The sRGB to
  CIELAB (D65, 2° observer) conversion is ``kornia.color.rgb_to_lab``, which equals
  ``skimage.color.rgb2lab`` (to 1e-13 in float64, checked in ``tests/metrics/test_colour_measures.py``).
  scikit-image's ``deltaE_ciede2000`` is NumPy only (no batches on the GPU), so the formula is
  written out here and checked against it and against Sharma's 34 published test pairs.
- :func:`piq_measures`: six non-learned full-reference measures of piq 0.8.0, called from piq:
  FSIMc, VIF (pixel domain), GMSD, HaarPSI, MDSI, VSI (:data:`PIQ_MEASURES`). GMSD and MDSI are
  distances (0 for equal images, :data:`LOWER_IS_BETTER_PIQ`), the others similarities (1 for
  equal images). FSIMc, HaarPSI, MDSI and VSI use the chroma; VIF and GMSD only the luma.

piq is not a dependency: ``scripts/bootstrap.sh`` installs it with ``pip install --no-deps`` because
its torchvision requirement would replace the CPU torch. Its package ``__init__`` imports
torchvision (for the learned measures), so ``import piq`` and even ``from piq.fsim import fsim``
fail without torchvision; the six modules used here need only torch and numpy and are loaded
without running that ``__init__`` (:func:`piq_functions`).
"""
from __future__ import annotations

import importlib
import importlib.util
import math
import sys
import threading
import types
from collections.abc import Callable, Sequence

import torch
import torch.nn.functional as F
from kornia.color import rgb_to_lab

from lit3d.utils.extras import MissingExtra, installed

# measure -> (piq module, function, extra keyword arguments)
_PIQ = {
    "fsim": ("fsim", "fsim", {"chromatic": True}),
    "vif": ("vif", "vif_p", {}),
    "gmsd": ("gmsd", "gmsd", {}),
    "haarpsi": ("haarpsi", "haarpsi", {}),
    "mdsi": ("mdsi", "mdsi", {}),
    "vsi": ("vsi", "vsi", {}),
}
PIQ_MEASURES = tuple(_PIQ)
LOWER_IS_BETTER_PIQ = frozenset({"gmsd", "mdsi"})  # distances; the other four are similarities
# smallest image side piq accepts: VIF's 4-scale valid-padded Gaussian pyramid needs 41 px, HaarPSI's
# 3-scale Haar filters 2 ** (3 + 1) = 16 px (it raises below); FSIM gives NaN on 1 px images
PIQ_MIN_SIZE = {"fsim": 2, "vif": 41, "gmsd": 1, "haarpsi": 16, "mdsi": 1, "vsi": 1}

_PIQ_LOCK = threading.Lock()
_PIQ_FUNCTIONS: dict[str, Callable] = {}


# --------------------------------------------------------------------------- CIEDE2000
def delta_e_ciede2000(lab1: torch.Tensor, lab2: torch.Tensor, dim: int = -3) -> torch.Tensor:
    """Per-pixel CIEDE2000 colour difference ΔE00 of two CIELAB tensors (channels L*, a*, b* on ``dim``).

    Sharma, Wu & Dalal (2005), "The CIEDE2000 color-difference formula: implementation notes,
    supplementary test data, and mathematical observations", eqs. (1)-(17) with
    ``kL = kC = kH = 1``: the hue of a zero chroma is 0, the mean hue is ``h1' + h2'`` when one
    chroma is 0. The hue difference ``Δh'`` is the angle between the two ``(a', b)`` vectors
    (``atan2`` of their cross and dot products, the paper's wrapped ``h2' - h1'``), and the mean
    hue ``h1' + Δh' / 2`` modulo 360°, which is the paper's case split; exactly opposite hues
    (``|h1' - h2'| = 180°``, where ΔE00 is discontinuous) take the paper's branch also in float32
    (a difference of two rounded ``atan2`` values would pick either, e.g. test pair 14: ΔE00 off by
    0.06). Computed in the inputs' dtype; the result has ``dim`` removed. In float32, colours
    within ~1e-7 rad of opposite hues may still take the other branch (by up to tens of ΔE00
    units for far-apart, saturated colours); float64 matches scikit-image to ~1e-13.
    """
    L1, a1, b1 = lab1.unbind(dim)
    L2, a2, b2 = lab2.unbind(dim)
    c_bar = 0.5 * (torch.hypot(a1, b1) + torch.hypot(a2, b2))
    c7 = c_bar**7
    g = 0.5 * (1 - torch.sqrt(c7 / (c7 + 25.0**7)))
    a1p, a2p = (1 + g) * a1, (1 + g) * a2
    c1p, c2p = torch.hypot(a1p, b1), torch.hypot(a2p, b2)
    two_pi = 2 * math.pi
    h1p = torch.where(c1p == 0, 0.0, torch.remainder(torch.atan2(b1, a1p), two_pi))  # radians in [0, 2 pi)
    h2p = torch.where(c2p == 0, 0.0, torch.remainder(torch.atan2(b2, a2p), two_pi))
    cc = c1p * c2p
    # h2' - h1' wrapped to [-pi, pi] (eq. 10), from the two hue vectors: no cancellation near +-pi
    cross, dot = a1p * b2 - b1 * a2p, a1p * a2p + b1 * b2
    dh = torch.atan2(cross, dot)
    tie = (cross == 0) & (dot < 0)  # opposite hues: Sharma keeps the unwrapped h2' - h1' = +-pi
    dh = torch.where(tie, math.pi * torch.sign(h2p - h1p), dh)
    dh = torch.where(cc == 0, 0.0, dh)
    d_lp = L2 - L1
    d_cp = c2p - c1p
    d_hp = 2 * torch.sqrt(cc) * torch.sin(0.5 * dh)
    l_bar = 0.5 * (L1 + L2)
    cp_bar = 0.5 * (c1p + c2p)
    h_sum = h1p + h2p
    # mean hue (eq. 14) in [0, 2 pi): h1' + dh / 2 is Sharma's case split, modulo 2 pi
    h_bar = torch.where(cc == 0, h_sum, torch.remainder(h1p + 0.5 * dh, two_pi))
    deg = math.pi / 180
    t = (1 - 0.17 * torch.cos(h_bar - 30 * deg) + 0.24 * torch.cos(2 * h_bar)
         + 0.32 * torch.cos(3 * h_bar + 6 * deg) - 0.20 * torch.cos(4 * h_bar - 63 * deg))
    d_theta = 30 * deg * torch.exp(-(((h_bar / deg - 275) / 25) ** 2))
    cp7 = cp_bar**7
    r_c = 2 * torch.sqrt(cp7 / (cp7 + 25.0**7))
    l50 = (l_bar - 50) ** 2
    s_l = 1 + 0.015 * l50 / torch.sqrt(20 + l50)
    s_c = 1 + 0.045 * cp_bar
    s_h = 1 + 0.015 * cp_bar * t
    r_t = -torch.sin(2 * d_theta) * r_c
    tl, tc, th = d_lp / s_l, d_cp / s_c, d_hp / s_h
    return torch.sqrt((tl**2 + tc**2 + th**2 + r_t * tc * th).clamp_min(0))


def ciede2000(a: torch.Tensor, b: torch.Tensor, mask_a: torch.Tensor, mask_b: torch.Tensor) -> torch.Tensor:
    """Mean CIEDE2000 ΔE00 per image ``(N,) float32`` over the union of the two masks.

    ``a``, ``b``: ``(N, 3, H, W)`` sRGB in ``[0, 1]``; ``mask_a``, ``mask_b``: ``(N, 1, H, W)`` or
    ``(1, 1, H, W)`` bool. Each image is taken as black outside its own mask (set to 0 there), so
    a pixel in only one mask compares that shape's colour against the black background, which is
    what an observer sees; pixels outside both masks are ignored. An empty union gives 0.
    sRGB -> CIELAB (D65) by ``kornia.color.rgb_to_lab``, ΔE00 by :func:`delta_e_ciede2000`, both
    in the images' dtype (float32 or float64), on the union's pixels only.
    """
    if a.shape != b.shape or a.ndim != 4 or a.shape[1] != 3:
        raise ValueError(f"ciede2000 needs two (N, 3, H, W) images of one shape, got {tuple(a.shape)}, "
                         f"{tuple(b.shape)}")
    n = a.shape[0]
    mask_a, mask_b = mask_a.bool(), mask_b.bool()
    if not a.is_floating_point():
        a, b = a.float(), b.float()
    union = (mask_a | mask_b).expand(n, 1, *a.shape[-2:]).reshape(n, -1)  # (N, HW)
    count = union.sum(1)

    def pixels(x, m):  # (3, P, 1): the union's pixels, black outside the image's own mask
        return (x * m).transpose(0, 1).reshape(3, -1)[:, union.reshape(-1), None]

    de = delta_e_ciede2000(rgb_to_lab(pixels(a, mask_a)), rgb_to_lab(pixels(b, mask_b)))[:, 0]  # (P,)
    total = torch.zeros(union.shape, dtype=de.dtype, device=de.device).masked_scatter_(union, de).sum(1)
    return (total / count.clamp_min(1)).float()


# --------------------------------------------------------------------------- piq
def _import_piq() -> dict[str, Callable]:
    return {name: getattr(importlib.import_module(f"piq.{mod}"), fn) for name, (mod, fn, _) in _PIQ.items()}


def piq_functions() -> dict[str, Callable]:
    """``{measure: piq function}`` for :data:`PIQ_MEASURES`, loaded once without torchvision.

    The modules ``piq.fsim``, ``piq.vif``, ... are imported under a stand-in ``piq`` package
    that skips piq's ``__init__`` (which imports torchvision); ``sys.modules`` is restored
    afterwards (the functions keep their modules). Raises :class:`~lit3d.utils.extras.MissingExtra` (an
    ``ImportError``) if piq is not installed.
    """
    with _PIQ_LOCK:
        if _PIQ_FUNCTIONS:
            return dict(_PIQ_FUNCTIONS)
        if not installed("piq"):  # not an extra of lit3d: pip would let piq's torchvision replace the CPU torch
            raise MissingExtra("the colour measures of coloured point clouds need piq: "
                               "pip install --no-deps piq==0.8.0 (--no-deps: piq's torchvision would replace torch)")
        spec = importlib.util.find_spec("piq") if "piq" not in sys.modules else None
        if spec is None:  # piq already imported (its __init__ ran: torchvision is there)
            loaded = _import_piq()
        else:
            saved = {k: v for k, v in sys.modules.items() if k == "piq" or k.startswith("piq.")}
            for k in saved:
                del sys.modules[k]
            package = types.ModuleType("piq")
            package.__path__ = list(spec.submodule_search_locations)
            sys.modules["piq"] = package
            try:
                loaded = _import_piq()
            finally:
                for k in [k for k in sys.modules if k == "piq" or k.startswith("piq.")]:
                    del sys.modules[k]
                sys.modules.update(saved)
        _PIQ_FUNCTIONS.update(loaded)
        return dict(loaded)


def piq_measures(a: torch.Tensor, b: torch.Tensor, measures: Sequence[str] = PIQ_MEASURES,
                 crop: tuple[int, int, int, int] | None = None, downsample: int = 1) -> dict[str, torch.Tensor]:
    """piq's colour full-reference measures per image: ``{measure: (N,) float32}``.

    Args:
        a, b: ``(N, 3, H, W)`` RGB in ``[0, 1]``, ``a`` the reference, ``b`` the distorted image
            (piq's order is ``(x, y) = (distorted, reference)``, so piq is called as ``f(b, a)``;
            VIF and MDSI are not symmetric).
        measures: subset of :data:`PIQ_MEASURES`.
        crop: ``(y0, x0, H, W)``: ``a``, ``b`` are the window at ``(y0, x0)`` of ``H x W``
            canvases that are 0 outside it (as in :func:`lit3d.features.view_measures.pair_measures`);
            they are zero-padded back to the canvas first, so the values are the full-canvas ones
            (all six measures pool global statistics; none has an exact crop shortcut).
        downsample: average ``downsample x downsample`` blocks of the (padded) images first (the
            feature table's reduction of these global measures, as for the grey FSIM).

    Each measure is piq's function with ``data_range=1.0, reduction="none"`` and its defaults:

    - ``fsim``: ``piq.fsim(chromatic=True)``, FSIMc; similarity, 1 for equal images. Averages
      F x F blocks first, ``F = max(1, round(min(H, W) / 256))``; luma is YIQ's Y (our grey
      :func:`lit3d.metrics.image.fsim` averages the channels), chroma YIQ's I and Q. At least 2 px.
    - ``vif``: ``piq.vif_p``, VIF in the pixel domain on BT.601 luma (no chroma); similarity, 1
      for equal images (up to ~1e-6). At least 41 x 41 px (piq raises below). A flat reference
      (e.g. all black) carries no information: VIF is then 1 whatever the distorted image.
    - ``gmsd``: ``piq.gmsd``, on YIQ luma (no chroma) averaged over 2 x 2 blocks; distance, 0
      for equal images.
    - ``haarpsi``: ``piq.haarpsi``, 3 Haar scales on YIQ after 2 x 2 averaging; similarity, 1 for
      equal images (up to ~5e-6 in float32). At least 16 x 16 px (piq raises below). Two
      all-black images give piq ``inf`` (zero weights, logit of 1); that is returned as 1.
    - ``mdsi``: ``piq.mdsi`` (``combination="sum"``), gradient and LHM chroma similarity;
      distance, 0 for equal images.
    - ``vsi``: ``piq.vsi``, visual-saliency-weighted similarity with LMN chroma; similarity, 1 for
      equal images.

    Raises ``ValueError`` for an unknown measure, a non-RGB input or an image smaller than
    :data:`PIQ_MIN_SIZE`, and ``ImportError`` if piq is not installed.
    """
    unknown = [m for m in measures if m not in _PIQ]
    if unknown:
        raise ValueError(f"unknown piq measures {unknown}; known: {PIQ_MEASURES}")
    if a.shape != b.shape or a.ndim != 4 or a.shape[1] != 3:
        raise ValueError(f"piq_measures needs two (N, 3, H, W) images of one shape, got {tuple(a.shape)}, "
                         f"{tuple(b.shape)}")
    if crop is not None:
        y0, x0, hh, ww = (int(v) for v in crop)
        h, w = a.shape[-2:]
        pad = (x0, ww - x0 - w, y0, hh - y0 - h)
        if min(pad) < 0:
            raise ValueError(f"crop {tuple(crop)} does not hold a {h} x {w} window")
        a, b = F.pad(a, pad), F.pad(b, pad)
    if downsample > 1:
        a, b = F.avg_pool2d(a, downsample), F.avg_pool2d(b, downsample)
    side = min(a.shape[-2:])
    small = [m for m in measures if side < PIQ_MIN_SIZE[m]]
    if small:
        raise ValueError(f"images of {tuple(a.shape[-2:])} px are too small for {small} "
                         f"(minimum sides {PIQ_MIN_SIZE})")
    if not a.is_floating_point():
        a, b = a.float(), b.float()
    functions = piq_functions()
    out = {}
    for m in measures:
        value = functions[m](b, a, data_range=1.0, reduction="none", **_PIQ[m][2])
        if m == "haarpsi":
            value = torch.where(torch.isfinite(value), value, torch.ones_like(value))
        out[m] = value.float()
    return out
