"""Colour renders of coloured shapes: unlit albedo and lit colour, each as RGB and luma.

Styles (names follow the MatCap styles' ``measure/style/shading`` feature naming):

- ``albedo_rgb`` / ``albedo_luma``: the visible point's (or vertex's) colour, unlit;
- ``lit_rgb`` / ``lit_luma``: the colour under the view's headlight (a directional light
  along the view direction, as for the MatCap styles): ``albedo * (AMBIENT + (1 - AMBIENT) n_z)``
  with ``n_z >= 0`` the view-space normal's component towards the camera;
- ``matcap_rgb`` / ``matcap_luma``: the colour under a MatCap's studio lighting (key, fill and rim
  lights of the :data:`MATCAP_LIGHT` style): ``albedo * grey(MatCap(n))``, what an observer sees of
  the coloured shape in a lit viewer, its colours and the shading of its geometry together.

Luma is ITU-R BT.601 (``0.299 R + 0.587 G + 0.114 B``, the grey of the MatCap styles).
Background pixels are 0.
"""
from __future__ import annotations

import torch

from lit3d.render.styles import apply_styles

COLOUR_STYLES = ("albedo_rgb", "albedo_luma", "lit_rgb", "lit_luma", "matcap_rgb", "matcap_luma")
AMBIENT = 0.3
MATCAP_LIGHT = "clay_studio"
_LUMA = (0.299, 0.587, 0.114)


def luma(rgb: torch.Tensor) -> torch.Tensor:
    """BT.601 luma ``(..., 1, H, W)`` of ``(..., 3, H, W)`` RGB."""
    w = torch.tensor(_LUMA, dtype=rgb.dtype, device=rgb.device).view(3, 1, 1)
    return (rgb * w).sum(-3, keepdim=True)


def apply_colour_styles(colour: torch.Tensor, normals: torch.Tensor, mask: torch.Tensor,
                        names: tuple[str, ...] = COLOUR_STYLES) -> dict[str, torch.Tensor]:
    """Colour styles of one G-buffer.

    Args:
        colour: ``(V, 3, H, W) float32`` albedo in ``[0, 1]``.
        normals: ``(V, 3, H, W) float32`` view-space unit normals (``+z`` towards the camera).
        mask: ``(V, 1, H, W) bool`` foreground.
        names: subset of :data:`COLOUR_STYLES`.

    Returns:
        ``{name: (V, C, H, W) float32}`` in ``[0, 1]``, ``C = 3`` for ``*_rgb``, 1 for ``*_luma``.
    """
    unknown = [n for n in names if n not in COLOUR_STYLES]
    if unknown:
        raise ValueError(f"unknown colour style(s) {unknown}; use {COLOUR_STYLES}")
    m = mask.to(colour.dtype)
    albedo = colour * m
    base = {"albedo": albedo}
    if any(n.startswith("lit_") for n in names):
        base["lit"] = albedo * (AMBIENT + (1.0 - AMBIENT) * normals[:, 2:3].clamp(0.0, 1.0))
    if any(n.startswith("matcap_") for n in names):
        base["matcap"] = albedo * apply_styles(normals, mask, [MATCAP_LIGHT], grey=True)[0]
    out = {}
    for n in names:
        kind, chan = n.split("_")
        out[n] = base[kind] if chan == "rgb" else luma(base[kind])
    return out
