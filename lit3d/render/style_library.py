"""The 30 MatCap styles of the quality task, as procedural functions of the view-space normal.

A MatCap colours a pixel from its view-space normal alone (orthographic form:
``uv = (n_x, n_y) * 0.496 + 0.5`` into a sphere image). Each style here is a
small documented torch function ``f(n) -> rgb`` on unit normals ``n`` of shape
``(N, 3, H, W)`` (camera looks down ``-z``; ``n_z > 0`` faces the camera),
returning ``(N, 3, H, W) float32`` in ``[0, 1]``. The lights are procedural
(:mod:`lit3d.render.style_terms`: Lambert, wrap lighting, Blinn-Phong, Fresnel rims,
checker and stripe reflections, toon bands, normal colours); nothing is copied from Blender.
Shading whole normal buffers with them: :mod:`lit3d.render.styles`.

Adding a style is one registry entry::

    @register("my_style")
    def my_style(n):
        \"\"\"One line on what it looks like.\"\"\"
        return _rgb(0.8, 0.2, 0.2) * lambert(n, KEY)
"""
from __future__ import annotations

import math
from collections.abc import Callable

import torch

from lit3d.render.style_terms import (
    CAM, FILL, KEY, SIDE, _col, _shade, _vec, blinn, dot, fresnel, lambert, reflect, smoothstep, stripes,
)

StyleFn = Callable[[torch.Tensor], torch.Tensor]
STYLES: dict[str, StyleFn] = {}


def register(name: str) -> Callable[[StyleFn], StyleFn]:
    """Decorator adding a style function to :data:`STYLES` under ``name``."""
    def deco(fn: StyleFn) -> StyleFn:
        if name in STYLES:
            raise ValueError(f"style {name!r} registered twice")
        STYLES[name] = fn
        return fn
    return deco


def style_names() -> list[str]:
    """Registered style names in registry order."""
    return list(STYLES)


def resolve_styles(spec: str | list[str] | tuple[str, ...] | None) -> list[str]:
    """``"all"``/None -> every style; a comma list or sequence -> validated names."""
    if spec is None or spec == "all":
        return style_names()
    names = [s.strip() for s in spec.split(",")] if isinstance(spec, str) else list(spec)
    names = [s.replace("-", "_").replace(" ", "_").replace("+", "_") for s in names if s]
    bad = [s for s in names if s not in STYLES]
    if bad:
        raise ValueError(f"unknown style(s) {', '.join(bad)}; known: {', '.join(STYLES)}")
    return names



@register("basic_1")
def basic_1(n):
    """Light grey plastic: key-light Lambert, soft ambient, broad white highlight."""
    return _shade(n, (0.78, 0.78, 0.78), lambert(n, KEY), 0.35 * blinn(n, KEY, 24), ambient=0.15)


@register("basic_2")
def basic_2(n):
    """Warm off-white plastic lit from the camera with a wide soft highlight."""
    return _shade(n, (0.85, 0.8, 0.72), lambert(n, CAM, wrap=0.3), 0.25 * blinn(n, CAM, 12), ambient=0.1)


@register("basic_dark")
def basic_dark(n):
    """Dark grey plastic with a tight highlight and a faint rim."""
    return _shade(n, (0.25, 0.25, 0.27), lambert(n, KEY), 0.6 * blinn(n, KEY, 80) + 0.25 * fresnel(n, 3.0),
                  ambient=0.1)


@register("basic_side")
def basic_side(n):
    """Grey plastic lit by a grazing side light: strong left/right gradient."""
    return _shade(n, (0.8, 0.8, 0.8), lambert(n, SIDE), 0.3 * blinn(n, SIDE, 30), ambient=0.08)


@register("brown")
def brown(n):
    """Glossy brown: key + fill diffuse, moderate highlight."""
    d = 0.8 * lambert(n, KEY) + 0.25 * lambert(n, FILL)
    return _shade(n, (0.5, 0.3, 0.16), d.clamp(max=1.0), 0.25 * blinn(n, KEY, 40), ambient=0.1)


@register("ceramic_dark")
def ceramic_dark(n):
    """Black glazed ceramic: near-black base, sharp mirror highlight, bright Fresnel rim."""
    return _shade(n, (0.07, 0.07, 0.09), lambert(n, KEY), 0.95 * blinn(n, KEY, 300) + 0.35 * fresnel(n, 4.0))


@register("ceramic_lightbulb")
def ceramic_lightbulb(n):
    """White ceramic reflecting a round light bulb: bright disc highlight in the mirror direction."""
    r = reflect(n)
    bulb = smoothstep(0.90, 0.94, dot(r, KEY))
    return _shade(n, (0.88, 0.87, 0.85), lambert(n, CAM, wrap=0.2), 0.8 * bulb, ambient=0.1).clamp(max=1.0)


@register("normal_y")
def normal_y(n):
    """"normal+y" check: blue below, yellow above, ramped by ``n_y``."""
    t = 0.5 * (n[:, 1:2] + 1.0)
    return _col((0.1, 0.2, 0.6), n) * (1.0 - t) + _col((0.95, 0.85, 0.2), n) * t


def _rim_checker(n, base, check):
    ang = torch.atan2(n[:, 1:2], n[:, 0:1]) / (2.0 * math.pi)
    rim = smoothstep(0.25, 0.6, 1.0 - n[:, 2:3].clamp(0.0, 1.0))
    chk = stripes(ang, 8.0, 0.3)
    return _col(base, n) * (0.2 + 0.8 * lambert(n, CAM)) * (1 - rim) + _col(check, n) * chk * rim


@register("check_rim_dark")
def check_rim_dark(n):
    """Dark body whose silhouette band carries a light angular checker."""
    return _rim_checker(n, (0.2, 0.2, 0.22), (0.9, 0.9, 0.9))


@register("check_rim_light")
def check_rim_light(n):
    """Light body whose silhouette band carries a dark-on-light angular checker."""
    r = _rim_checker(n, (0.85, 0.85, 0.85), (0.15, 0.15, 0.15))
    rim = smoothstep(0.25, 0.6, 1.0 - n[:, 2:3].clamp(0.0, 1.0))
    return r + rim * 0.5 * _col((0.85, 0.85, 0.85), n) * (1 - stripes(
        torch.atan2(n[:, 1:2], n[:, 0:1]) / (2.0 * math.pi), 8.0, 0.3))


@register("clay_brown")
def clay_brown(n):
    """Terracotta clay: wrapped diffuse, no gloss."""
    return _shade(n, (0.6, 0.36, 0.24), lambert(n, KEY, wrap=0.4), ambient=0.12)


@register("clay_muddy")
def clay_muddy(n):
    """Muddy grey-green clay lit from the camera, very soft."""
    return _shade(n, (0.48, 0.44, 0.36), lambert(n, CAM, wrap=0.6), ambient=0.15)


@register("clay_studio")
def clay_studio(n):
    """Neutral studio clay: key, fill and a cool rim light."""
    d = 0.75 * lambert(n, KEY, wrap=0.2) + 0.3 * lambert(n, FILL)
    return _shade(n, (0.72, 0.7, 0.66), d.clamp(max=1.0), 0.2 * fresnel(n, 2.5), (0.6, 0.7, 0.9), ambient=0.08)


@register("dark_grey")
def dark_grey(n):
    """Dark grey satin from the camera light."""
    return _shade(n, (0.28, 0.28, 0.28), lambert(n, CAM), 0.2 * blinn(n, CAM, 20), ambient=0.1)


@register("jade")
def jade(n):
    """Jade: green translucent (wrap light), glossy highlight, pale Fresnel edge."""
    return _shade(n, (0.3, 0.62, 0.42), lambert(n, KEY, wrap=0.7), 0.45 * blinn(n, KEY, 60)
                  + 0.25 * fresnel(n, 2.0), (0.8, 1.0, 0.9), ambient=0.1).clamp(max=1.0)


@register("matt_blue")
def matt_blue(n):
    """Matte blue Lambert under the key light."""
    return _shade(n, (0.25, 0.4, 0.78), lambert(n, KEY), ambient=0.1)


@register("matt_brown")
def matt_brown(n):
    """Matte brown Lambert under the camera light."""
    return _shade(n, (0.52, 0.34, 0.2), lambert(n, CAM), ambient=0.05)


@register("metal_anisotropic")
def metal_anisotropic(n):
    """Brushed metal: highlight stretched horizontally (anisotropic lobe in the mirror direction)."""
    r = reflect(n)
    lobe = torch.exp(-((r[:, 1:2] - KEY[1]) ** 2) / 0.01 - ((r[:, 0:1] - KEY[0]) ** 2) / 0.4)
    env = 0.3 + 0.25 * r[:, 1:2]
    return (_col((0.6, 0.6, 0.62), n) * env + _col((1.0, 1.0, 1.0), n) * 0.8 * lobe).clamp(0.0, 1.0)


@register("metal_car_paint")
def metal_car_paint(n):
    """Red car paint: metallic base colour, clear-coat highlight, colour-shifted rim."""
    return _shade(n, (0.62, 0.05, 0.06), lambert(n, KEY) ** 1.5, 0.9 * blinn(n, KEY, 400)
                  + 0.3 * fresnel(n, 3.0), (1.0, 0.8, 0.8), ambient=0.05).clamp(max=1.0)


@register("metal_lead")
def metal_lead(n):
    """Dull lead: low-contrast environment gradient seen in the mirror direction."""
    r = reflect(n)
    return (_col((0.35, 0.36, 0.38), n) + _col((0.25, 0.25, 0.25), n) * r[:, 1:2]
            + 0.15 * blinn(n, KEY, 10)).clamp(0.0, 1.0)


@register("metal_shiny")
def metal_shiny(n):
    """Chrome: mirror of a bright sky over a dark ground with a sharp horizon and a sun."""
    r = reflect(n)
    sky = smoothstep(-0.05, 0.05, r[:, 1:2])
    sun = smoothstep(0.95, 0.98, dot(r, KEY))
    return (_col((0.12, 0.1, 0.09), n) * (1 - sky) + _col((0.75, 0.82, 0.95), n) * sky * (0.6 + 0.4 * r[:, 1:2])
            + sun).clamp(0.0, 1.0)


@register("orange_blue")
def orange_blue(n):
    """Two-tone: warm orange light from the left, cool blue light from the right."""
    warm = lambert(n, _vec(-1.0, 0.3, 0.5))
    cool = lambert(n, _vec(1.0, -0.1, 0.5))
    return (_col((0.95, 0.5, 0.1), n) * warm + _col((0.15, 0.35, 0.9), n) * cool).clamp(0.0, 1.0)


@register("pearl")
def pearl(n):
    """Pearl: soft white with an iridescent hue that cycles with the viewing angle."""
    t = n[:, 2:3].clamp(0.0, 1.0)
    phase = 2.0 * math.pi * (1.5 * t)
    hue = torch.cat([0.5 + 0.5 * torch.cos(phase), 0.5 + 0.5 * torch.cos(phase - 2.1),
                     0.5 + 0.5 * torch.cos(phase - 4.2)], 1)
    base = 0.55 + 0.35 * lambert(n, CAM, wrap=0.5)
    return (base * (0.75 + 0.25 * hue) + 0.3 * blinn(n, KEY, 50)).clamp(0.0, 1.0)


@register("reflection_check_horizontal")
def reflection_check_horizontal(n):
    """Mirror of a horizontally striped environment (stripes in the reflected elevation)."""
    r = reflect(n)
    s = stripes(torch.asin(r[:, 1:2].clamp(-1.0, 1.0)) / math.pi, 4.0)
    return _col((0.1, 0.1, 0.1), n) + _col((0.8, 0.8, 0.8), n) * s


@register("reflection_check_vertical")
def reflection_check_vertical(n):
    """Mirror of a vertically striped environment (stripes in the reflected azimuth)."""
    r = reflect(n)
    s = stripes(torch.asin(r[:, 0:1].clamp(-1.0, 1.0)) / math.pi, 4.0)
    return _col((0.1, 0.1, 0.1), n) + _col((0.8, 0.8, 0.8), n) * s


@register("resin")
def resin(n):
    """Amber resin: deep translucent core, glowing Fresnel edge, sharp highlight."""
    return _shade(n, (0.45, 0.2, 0.03), lambert(n, CAM, wrap=0.5), 0.9 * blinn(n, KEY, 150)
                  + 0.5 * fresnel(n, 2.0), (1.0, 0.75, 0.4), ambient=0.1).clamp(max=1.0)


@register("skin")
def skin(n):
    """Skin: wrapped diffuse with a reddish terminator and a soft sheen."""
    d = lambert(n, KEY, wrap=0.5)
    red = (d * (1.0 - d)) * 0.5
    return (_col((0.88, 0.64, 0.52), n) * (0.12 + 0.88 * d) + _col((0.5, 0.05, 0.02), n) * red
            + 0.12 * blinn(n, KEY, 20)).clamp(0.0, 1.0)


@register("toon")
def toon(n):
    """Toon: three flat diffuse bands, a hard highlight spot and a dark outline."""
    d = lambert(n, KEY)
    bands = 0.35 + 0.3 * smoothstep(0.2, 0.23, d) + 0.25 * smoothstep(0.6, 0.63, d)
    spot = smoothstep(0.9, 0.92, blinn(n, KEY, 1.0) ** 40)
    outline = 1.0 - smoothstep(0.25, 0.3, n[:, 2:3])
    return (_col((0.95, 0.7, 0.35), n) * bands + 0.3 * spot) * (1.0 - outline)


@register("normal_rgb")
def normal_rgb(n):
    """Normal map colours ``(n + 1) / 2`` (x red, y green, z blue)."""
    return 0.5 * (n + 1.0)


@register("lambert_white")
def lambert_white(n):
    """White Lambert under a directional light along the view direction (the thesis's light)."""
    return lambert(n, CAM).expand(-1, 3, -1, -1)
