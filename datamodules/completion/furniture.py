"""Procedural ShapeNet-like shapes: the seen categories and the catalogue of all categories.

Seen categories (training): bench, chair, couch, table, each assembled from parts with
random proportions and styles (this module). Unseen categories (test only): car, faucet,
firearm, guitar, monitor, plane (:mod:`datamodules.completion.unseen_shapes`). Both are built
from the analytic primitives of :mod:`datamodules.completion.primitives`; :func:`make_shape`
draws a shape of any category (names: :mod:`lit3d.utils.shapenet_categories`).
"""
from __future__ import annotations

from collections.abc import Callable

import numpy as np

from datamodules.completion.primitives import Primitive, Shape, beam, box, cylinder, ellipsoid, pose, rot_x, rot_y
from datamodules.completion.primitives import shape_mesh  # noqa: F401 (imported from here by depth_voxels)
from datamodules.completion.unseen_shapes import car, faucet, firearm, guitar, monitor, plane


# ---------------------------------------------------------------- parts
def _legs(rng, style: str, w: float, d: float, h: float, t: float, inset: float = 0.0) -> list[Primitive]:
    """Support of a seat/top of width w, depth d whose underside is at height h."""
    parts: list[Primitive] = []
    if style == "four":
        round_ = rng.random() < 0.4
        splay = rng.uniform(0, 0.04) if rng.random() < 0.4 else 0.0
        for sx in (-1, 1):
            for sz in (-1, 1):
                top = np.array([sx * (w / 2 - t / 2 - inset), h, sz * (d / 2 - t / 2 - inset)])
                bot = top + np.array([sx * splay, -h, sz * splay])
                parts.append(cylinder(bot, top, t / 2) if round_ else beam(bot, top, t, t))
        if rng.random() < 0.5:  # stretchers
            y = h * rng.uniform(0.15, 0.35)
            for sx in (-1, 1):
                parts.append(box((sx * (w / 2 - t / 2 - inset), y, 0), (t * 0.7, t * 0.7, d - 2 * inset)))
    elif style == "pedestal":
        r = min(w, d) * rng.uniform(0.05, 0.09)
        parts.append(cylinder((0, 0.03, 0), (0, h, 0), r))
        if rng.random() < 0.5:
            parts.append(cylinder((0, 0, 0), (0, 0.04, 0), min(w, d) * rng.uniform(0.3, 0.45)))
        else:  # star base
            n = int(rng.integers(4, 6))
            arm = min(w, d) * rng.uniform(0.4, 0.55)
            for k in range(n):
                a = 360.0 * k / n + rng.uniform(-5, 5)
                dirv = rot_y(a) @ np.array([1.0, 0, 0])
                parts.append(Primitive("box", (arm, 0.04, 0.05), pose(dirv * arm / 2 + [0, 0.03, 0], rot_y(a))))
    elif style == "sled":
        for sx in (-1, 1):
            x = sx * (w / 2 - t / 2 - inset)
            parts.append(box((x, t / 2, 0), (t, t, d * rng.uniform(0.9, 1.1))))
            for sz in (-1, 1):
                z = sz * (d / 2 - t / 2 - inset)
                parts.append(beam((x, 0, z), (x, h, z), t, t))
    elif style == "panel":
        pt = t * rng.uniform(0.8, 1.5)
        for sx in (-1, 1):
            parts.append(box((sx * (w / 2 - pt / 2 - inset), h / 2, 0), (pt, h, d * rng.uniform(0.8, 1.0))))
    else:
        raise ValueError(style)
    return parts


def _back(rng, style: str, w: float, y0: float, hb: float, z: float, t: float, tilt: float) -> list[Primitive]:
    """A back rest from height y0 up by hb, at depth z (rear), tilted back by ``tilt`` degrees."""
    rot = rot_x(-tilt)
    def at(local):  # local point relative to the back's bottom centre, tilted
        return np.array([0, y0, z]) + rot @ np.asarray(local, float)
    parts: list[Primitive] = []
    if style == "solid":
        parts.append(Primitive("box", (w, hb, t), pose(at((0, hb / 2, 0)), rot)))
    else:  # slatted: two posts, a top rail, vertical or horizontal slats
        post = t * 1.2
        for sx in (-1, 1):
            parts.append(Primitive("box", (post, hb, t), pose(at((sx * (w / 2 - post / 2), hb / 2, 0)), rot)))
        rail = hb * rng.uniform(0.12, 0.25)
        parts.append(Primitive("box", (w, rail, t), pose(at((0, hb - rail / 2, 0)), rot)))
        inner = w - 2 * post
        if rng.random() < 0.5:
            n = int(rng.integers(2, 6))
            sw = inner / (2 * n + 1)
            for k in range(n):
                x = -inner / 2 + sw * (2 * k + 1.5)
                parts.append(Primitive("box", (sw, hb - rail, t * 0.7), pose(at((x, (hb - rail) / 2, 0)), rot)))
        else:
            n = int(rng.integers(1, 4))
            for k in range(n):
                y = (hb - rail) * (k + 1) / (n + 1)
                parts.append(Primitive("box", (inner, rail * 0.6, t * 0.7), pose(at((0, y, 0)), rot)))
    return parts


def chair(rng: np.random.Generator) -> Shape:
    w, d = rng.uniform(0.42, 0.6), rng.uniform(0.4, 0.55)
    h, t = rng.uniform(0.4, 0.5), rng.uniform(0.04, 0.08)
    leg = rng.uniform(0.03, 0.05)
    style = rng.choice(["four", "four", "pedestal", "sled"])
    parts = [box((0, h + t / 2, 0), (w, t, d))]
    parts += _legs(rng, str(style), w, d, h, leg)
    hb = rng.uniform(0.35, 0.6)
    bt = rng.uniform(0.03, 0.06)
    parts += _back(rng, str(rng.choice(["solid", "slatted"])), w, h + t, hb, -d / 2 + bt / 2, bt, rng.uniform(0, 15))
    if rng.random() < 0.4:  # arms
        ah = rng.uniform(0.18, 0.28)
        aw = rng.uniform(0.04, 0.07)
        for sx in (-1, 1):
            x = sx * (w / 2 - aw / 2)
            parts.append(box((x, h + t + ah, 0), (aw, 0.04, d * 0.9)))
            parts.append(beam((x, h + t, d / 2 - 0.05), (x, h + t + ah, d / 2 - 0.05), aw * 0.8, 0.04))
    return Shape("chair", parts)


def table(rng: np.random.Generator) -> Shape:
    w, d = rng.uniform(0.8, 1.6), rng.uniform(0.5, 1.0)
    h, t = rng.uniform(0.65, 0.78), rng.uniform(0.03, 0.07)
    round_top = rng.random() < 0.25
    if round_top:
        d = w = rng.uniform(0.7, 1.2)
        parts = [Primitive("cylinder", (w / 2, t), pose((0, h + t / 2, 0), rot_x(90)))]
    else:
        parts = [box((0, h + t / 2, 0), (w, t, d))]
    style = str(rng.choice(["pedestal"] if round_top and rng.random() < 0.6 else ["four", "four", "panel", "pedestal"]))
    leg = rng.uniform(0.04, 0.08)
    inset = 0.0 if not round_top else w * 0.15
    parts += _legs(rng, style, w, d, h, leg, inset=inset)
    if not round_top and style != "pedestal":
        if rng.random() < 0.5:  # apron
            ah = rng.uniform(0.06, 0.12)
            parts.append(box((0, h - ah / 2, d / 2 - leg), (w - 2 * leg, ah, 0.02)))
            parts.append(box((0, h - ah / 2, -d / 2 + leg), (w - 2 * leg, ah, 0.02)))
        if rng.random() < 0.4:  # shelf
            parts.append(box((0, h * rng.uniform(0.15, 0.35), 0), (w - 2 * leg, 0.03, d - 2 * leg)))
    return Shape("table", parts)


def bench(rng: np.random.Generator) -> Shape:
    w, d = rng.uniform(1.2, 2.0), rng.uniform(0.3, 0.5)
    h, t = rng.uniform(0.38, 0.5), rng.uniform(0.04, 0.07)
    parts: list[Primitive] = []
    if rng.random() < 0.5:  # slatted seat
        n = int(rng.integers(3, 6))
        sd = d / (n + (n - 1) * 0.3)
        for k in range(n):
            z = -d / 2 + sd / 2 + k * sd * 1.3
            parts.append(box((0, h + t / 2, z), (w, t, sd)))
    else:
        parts.append(box((0, h + t / 2, 0), (w, t, d)))
    parts += _legs(rng, str(rng.choice(["four", "panel", "sled"])), w, d, h, rng.uniform(0.04, 0.07),
                   inset=w * rng.uniform(0, 0.08))
    if rng.random() < 0.5:
        bt = 0.04
        parts += _back(rng, str(rng.choice(["solid", "slatted"])), w, h + t, rng.uniform(0.25, 0.45), -d / 2 + bt / 2, bt,
                       rng.uniform(0, 12))
    return Shape("bench", parts)


def couch(rng: np.random.Generator) -> Shape:
    w, d = rng.uniform(1.5, 2.4), rng.uniform(0.8, 1.0)
    base_y, base_h = rng.uniform(0.05, 0.15), rng.uniform(0.15, 0.25)
    parts: list[Primitive] = []
    if base_y > 0.08:  # short legs
        lt = 0.05
        for sx in (-1, 1):
            for sz in (-1, 1):
                parts.append(box((sx * (w / 2 - 0.08), base_y / 2, sz * (d / 2 - 0.08)), (lt, base_y, lt)))
    else:
        base_h += base_y
        base_y = 0.0
    parts.append(box((0, base_y + base_h / 2, 0), (w, base_h, d)))
    top = base_y + base_h
    back_t = rng.uniform(0.15, 0.25)
    back_h = rng.uniform(0.35, 0.55)
    parts.append(box((0, top + back_h / 2, -d / 2 + back_t / 2), (w, back_h, back_t)))
    arms = str(rng.choice(["box", "rolled", "none"], p=[0.5, 0.3, 0.2]))
    arm_w = rng.uniform(0.12, 0.22) if arms != "none" else 0.0
    arm_h = rng.uniform(0.15, 0.3)
    for sx in (-1, 1):
        x = sx * (w / 2 - arm_w / 2)
        if arms == "box":
            parts.append(box((x, top + arm_h / 2, 0), (arm_w, arm_h, d)))
        elif arms == "rolled":
            parts.append(box((x, top + arm_h / 2 - arm_w / 4, 0), (arm_w, arm_h - arm_w / 2, d)))
            parts.append(Primitive("cylinder", (arm_w / 2, d), pose((x, top + arm_h - arm_w / 2, 0))))
    n = int(rng.integers(1, 4))
    cw = (w - 2 * arm_w) / n
    ch = rng.uniform(0.08, 0.15)
    cd = d - back_t
    for k in range(n):
        x = -w / 2 + arm_w + cw * (k + 0.5)
        parts.append(box((x, top + ch / 2, -d / 2 + back_t + cd / 2), (cw * 0.96, ch, cd * 0.98)))
        if rng.random() < 0.6:  # back cushion
            parts.append(ellipsoid((x, top + ch + back_h * 0.4, -d / 2 + back_t + 0.05), (cw * 0.47, back_h * 0.35, 0.08)))
    if rng.random() < 0.25:  # chaise (L shape)
        sx = rng.choice([-1, 1])
        ext = rng.uniform(0.5, 0.8)
        parts.append(box((sx * (w / 2 - cw / 2 - arm_w), base_y + base_h / 2, d / 2 + ext / 2), (cw, base_h, ext)))
    return Shape("couch", parts)


GENERATORS: dict[str, Callable[[np.random.Generator], Shape]] = {
    "bench": bench, "chair": chair, "couch": couch, "table": table,
    "car": car, "faucet": faucet, "firearm": firearm, "guitar": guitar, "monitor": monitor, "plane": plane,
}


def make_shape(category: str, rng: np.random.Generator) -> Shape:
    """A random shape of ``category`` (one of :data:`GENERATORS`) drawn from ``rng``."""
    try:
        gen = GENERATORS[category]
    except KeyError:
        raise ValueError(f"unknown synthetic category {category!r}; known: {sorted(GENERATORS)}") from None
    return gen(rng)
