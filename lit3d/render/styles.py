"""Shading normal buffers with the MatCap styles (:mod:`lit3d.render.style_library`).

Rendering many styles: :func:`bake_luts` evaluates every style once on a
``T x T`` grid over the unit disc (the MatCap image) and :func:`apply_styles`
looks all styles up for a whole batch of normal buffers with one
``grid_sample`` call (bilinear) — that is what a MatCap renderer does, and it
costs one pass for 30 styles x 12 views. ``mode="direct"`` evaluates the
functions per pixel instead (exact; used to check the look-up).

The registry names (:data:`STYLES`, :func:`register`, :func:`resolve_styles`,
:func:`style_names`) are importable from here too.
"""
from __future__ import annotations

import functools

import torch
import torch.nn.functional as F

from lit3d.render.style_library import STYLES, StyleFn, register, resolve_styles, style_names

__all__ = ["LUT_SIZE", "STYLES", "StyleFn", "apply_styles", "bake_luts", "disc_normals", "register",
           "resolve_styles", "style_names"]

LUT_SIZE = 256


def disc_normals(size: int = LUT_SIZE, device=None) -> torch.Tensor:
    """Unit normals ``(1, 3, T, T)`` on a grid over ``(n_x, n_y) in [-1, 1]^2``.

    Row ``i`` holds ``n_y = -1 + 2 i / (T - 1)``, column ``j`` ``n_x``; points outside
    the unit disc are projected onto its rim (``n_z = 0``).
    """
    t = torch.linspace(-1.0, 1.0, size, device=device)
    ny, nx = torch.meshgrid(t, t, indexing="ij")
    r = torch.sqrt(nx * nx + ny * ny).clamp_min(1.0)
    nx, ny = nx / r, ny / r
    nz = (1.0 - nx * nx - ny * ny).clamp_min(0.0).sqrt()
    return torch.stack([nx, ny, nz])[None]


@functools.lru_cache(maxsize=16)
def _bake(names: tuple[str, ...], size: int, device: str) -> torch.Tensor:
    n = disc_normals(size, device)
    return torch.cat([STYLES[s](n).clamp(0.0, 1.0).float() for s in names], 0)  # (S, 3, T, T)


@functools.lru_cache(maxsize=16)
def _bake_grey(names: tuple[str, ...], size: int, device: str) -> torch.Tensor:
    lut = _bake(names, size, device)
    w = torch.tensor([0.299, 0.587, 0.114], device=lut.device).view(1, 3, 1, 1)
    return (lut * w).sum(1, keepdim=True)


@functools.lru_cache(maxsize=16)
def _texel_table(names: tuple[str, ...], size: int, device: str, grey: bool) -> torch.Tensor:
    """``(T * T, S * C)`` contiguous: one row per texel, so a look-up reads adjacent values."""
    lut = _bake_grey(names, size, device) if grey else _bake(names, size, device)
    return lut.flatten(0, 1).flatten(1).t().contiguous()


def bake_luts(names: list[str] | None = None, size: int = LUT_SIZE, device=None, grey: bool = False) -> torch.Tensor:
    """MatCap images ``(S, 3, T, T)`` (``(S, 1, T, T)`` luma with ``grey``) of the named styles."""
    names = tuple(resolve_styles(names))
    dev = str(torch.device(device) if device is not None else torch.device("cpu"))
    return _bake_grey(names, size, dev) if grey else _bake(names, size, dev)


def apply_styles(normals: torch.Tensor, mask: torch.Tensor, names: list[str] | None = None, *,
                 grey: bool = False, mode: str = "lut", background: float = 0.0,
                 lut_size: int = LUT_SIZE) -> torch.Tensor:
    """Shade normal buffers with every named style in one pass.

    Args:
        normals: ``(V, 3, H, W) float32`` view-space unit normals.
        mask: ``(V, 1, H, W) bool`` foreground.
        names: style names (default all 30).
        grey: return luma ``C = 1`` instead of RGB ``C = 3``.
        mode: ``"lut"`` (bilinear MatCap look-up, one ``grid_sample`` for all styles)
            or ``"direct"`` (evaluate the style functions per pixel).
        background: value of background pixels.

    Returns:
        ``(S, V, C, H, W) float32`` in ``[0, 1]``.
    """
    names = resolve_styles(names)
    v, _, h, w = normals.shape
    m = mask.bool()
    if mode == "direct":
        outs = []
        nn_ = F.normalize(normals.float(), dim=1)
        for s in names:
            img = STYLES[s](nn_).clamp(0.0, 1.0)
            if grey:
                wt = torch.tensor([0.299, 0.587, 0.114], device=img.device).view(1, 3, 1, 1)
                img = (img * wt).sum(1, keepdim=True)
            outs.append(torch.where(m, img, torch.full_like(img, background)))
        return torch.stack(outs)
    if mode != "lut":
        raise ValueError(f"unknown style mode {mode!r}")
    c, t = (1 if grey else 3), lut_size
    table = _texel_table(tuple(names), t, str(normals.device), grey)  # (T*T, S*C)
    sc = table.shape[1]
    flat_mask = m.reshape(-1)  # (V*H*W,) foreground pixels only are looked up
    fg = flat_mask.nonzero().squeeze(1)
    nrm = normals[:, :2].permute(0, 2, 3, 1).reshape(-1, 2)[fg].float()
    # bilinear look-up: texel (row, col) = ((n_y + 1) / 2, (n_x + 1) / 2) * (T - 1)
    uv = ((nrm.clamp(-1.0, 1.0) + 1.0) * (0.5 * (t - 1)))
    i0 = uv.floor().clamp(0, t - 2)
    fr = uv - i0
    i0 = i0.long()
    idx = i0[:, 1] * t + i0[:, 0]
    fx, fy = fr[:, 0:1], fr[:, 1:2]
    top = torch.lerp(table[idx], table[idx + 1], fx)  # (N, S*C) rows of adjacent texels
    bot = torch.lerp(table[idx + t], table[idx + t + 1], fx)
    val = torch.lerp(top, bot, fy)
    out = torch.full((v * h * w, sc), float(background), dtype=torch.float32, device=normals.device)
    out[fg] = val
    return out.view(v, h, w, len(names), c).permute(3, 0, 4, 1, 2).contiguous()
