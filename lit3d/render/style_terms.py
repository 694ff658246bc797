"""Lights and shading terms of the MatCap styles (:mod:`lit3d.render.style_library`).

Every term takes unit view-space normals ``n`` ``(N, 3, H, W)`` (camera looks down ``-z``;
``n_z > 0`` faces the camera) and returns ``(N, 1, H, W)`` (``(N, 3, H, W)`` for colours and
:func:`reflect`) in the dtype and device of ``n``. Directions are unit 3-tuples.
"""
from __future__ import annotations

import math

import torch


def _vec(x: float, y: float, z: float) -> tuple[float, float, float]:
    n = math.sqrt(x * x + y * y + z * z)
    return (x / n, y / n, z / n)


CAM = (0.0, 0.0, 1.0)            # light along the view direction (the thesis's camera light)
KEY = _vec(-0.45, 0.55, 0.75)    # studio key light, upper left
FILL = _vec(0.6, -0.2, 0.6)      # softer fill from the lower right
SIDE = _vec(1.0, 0.15, 0.35)     # grazing side light


def _rgb(r: float, g: float, b: float) -> tuple[float, float, float]:
    return (r, g, b)


def _col(c, ref: torch.Tensor) -> torch.Tensor:
    return torch.tensor(c, dtype=ref.dtype, device=ref.device).view(1, 3, 1, 1)


def dot(n: torch.Tensor, d) -> torch.Tensor:
    """``n . d`` as ``(N, 1, H, W)`` for a fixed direction ``d``."""
    return n[:, 0:1] * d[0] + n[:, 1:2] * d[1] + n[:, 2:3] * d[2]


def lambert(n: torch.Tensor, d, wrap: float = 0.0) -> torch.Tensor:
    """Diffuse term ``max(0, (n.d + wrap) / (1 + wrap))``; ``wrap > 0`` mimics sub-surface light."""
    return ((dot(n, d) + wrap) / (1.0 + wrap)).clamp_min(0.0)


def blinn(n: torch.Tensor, d, power: float) -> torch.Tensor:
    """Blinn-Phong highlight ``max(0, n.h) ** power``, ``h`` halfway between light and view."""
    h = _vec(d[0] + CAM[0], d[1] + CAM[1], d[2] + CAM[2])
    return dot(n, h).clamp_min(0.0) ** power


def fresnel(n: torch.Tensor, power: float = 3.0) -> torch.Tensor:
    """Rim term ``(1 - n_z) ** power`` (Schlick-like), 0 facing the camera, 1 at the silhouette."""
    return (1.0 - n[:, 2:3].clamp(0.0, 1.0)) ** power


def reflect(n: torch.Tensor) -> torch.Tensor:
    """Mirror direction of the view ray, ``r = 2 n_z n - v`` with ``v = (0, 0, 1)``, ``(N, 3, H, W)``."""
    r = 2.0 * n[:, 2:3] * n
    return torch.cat([r[:, 0:1], r[:, 1:2], r[:, 2:3] - 1.0], 1)


def smoothstep(e0: float, e1: float, x: torch.Tensor) -> torch.Tensor:
    """Hermite step from 0 at ``e0`` to 1 at ``e1``."""
    t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def stripes(x: torch.Tensor, freq: float, soft: float = 0.15) -> torch.Tensor:
    """Soft square wave of ``x`` in ``[0, 1]`` with ``freq`` periods per unit."""
    return smoothstep(-soft, soft, torch.sin(2.0 * math.pi * freq * x))


def _shade(n, base, diffuse, spec=0.0, spec_col=(1.0, 1.0, 1.0), ambient=0.0):
    return _col(base, n) * (ambient + (1.0 - ambient) * diffuse) + _col(spec_col, n) * spec
