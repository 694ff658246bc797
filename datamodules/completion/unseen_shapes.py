"""Procedural shapes of the unseen categories (test only): car, faucet, firearm, guitar, monitor,
plane (:data:`~lit3d.utils.shapenet_categories.UNSEEN_CATEGORIES`). Built from the primitives
of :mod:`datamodules.completion.primitives`; catalogue: :data:`datamodules.completion.furniture.GENERATORS`.
"""
from __future__ import annotations

import numpy as np

from datamodules.completion.primitives import Primitive, Shape, box, cylinder, ellipsoid, pose, rot_x, rot_y, torus


def car(rng: np.random.Generator) -> Shape:
    L, W = rng.uniform(3.8, 4.8), rng.uniform(1.6, 1.9)
    r = rng.uniform(0.3, 0.38)
    body_h = rng.uniform(0.5, 0.7)
    clear = r * 0.6
    parts = [box((0, clear + body_h / 2, 0), (W, body_h, L))]
    cab_l = L * rng.uniform(0.4, 0.55)
    cab_h = rng.uniform(0.4, 0.55)
    parts.append(box((0, clear + body_h + cab_h / 2, -L * rng.uniform(0.0, 0.12)), (W * 0.85, cab_h, cab_l)))
    if rng.random() < 0.5:  # rounded hood
        parts.append(ellipsoid((0, clear + body_h, L * 0.3), (W * 0.45, 0.12, L * 0.2)))
    for sx in (-1, 1):
        for sz in (-1, 1):
            c = (sx * (W / 2 - 0.12), r, sz * L * 0.32)
            if rng.random() < 0.5:
                parts.append(Primitive("cylinder", (r, 0.24), pose(c, rot_y(90))))
            else:
                parts.append(torus(c, r * 0.68, r * 0.32, rot_y(90)))
    return Shape("car", parts)


def monitor(rng: np.random.Generator) -> Shape:
    sw, sh = rng.uniform(0.5, 0.7), rng.uniform(0.3, 0.45)
    st = rng.uniform(0.02, 0.05)
    neck = rng.uniform(0.1, 0.2)
    parts = [box((0, neck + sh / 2, 0), (sw, sh, st))]
    parts.append(box((0, neck / 2 + 0.01, -st), (0.05, neck + sh * 0.4, 0.03)))
    if rng.random() < 0.3:  # back bulge (old CRT-ish)
        parts.append(box((0, neck + sh / 2, -st / 2 - 0.06), (sw * 0.6, sh * 0.6, 0.12)))
    if rng.random() < 0.5:
        parts.append(Primitive("cylinder", (rng.uniform(0.1, 0.15), 0.02), pose((0, 0.01, -st), rot_x(90))))
    else:
        parts.append(box((0, 0.01, -st), (rng.uniform(0.2, 0.3), 0.02, rng.uniform(0.12, 0.2))))
    return Shape("monitor", parts)


def faucet(rng: np.random.Generator) -> Shape:
    h = rng.uniform(0.15, 0.3)
    r = rng.uniform(0.015, 0.025)
    reach = rng.uniform(0.1, 0.2)
    parts = [Primitive("cylinder", (r * 2.2, 0.02), pose((0, 0.01, 0), rot_x(90)))]
    parts.append(cylinder((0, 0, 0), (0, h, 0), r))
    if rng.random() < 0.5:  # gooseneck: up, arch forward, down (three tube segments + elbows)
        top = h + reach * 0.5
        a, b, c = (0, h, 0), (0, top, reach * 0.35), (0, top, reach)
        parts.append(cylinder(a, b, r))
        parts.append(cylinder(b, c, r))
        parts.append(cylinder(c, (0, top - reach * 0.4, reach * 1.05), r))
        parts += [ellipsoid(b, (r, r, r)), ellipsoid(c, (r, r, r))]
    else:
        parts.append(cylinder((0, h - r, -r), (0, h - r * 0.2, reach), r))
        parts.append(cylinder((0, h - 0.04, reach), (0, h - r * 0.5, reach), r * 1.1))
    # lever handle
    parts.append(cylinder((0, h * rng.uniform(0.6, 0.9), 0), (rng.choice([-1, 1]) * rng.uniform(0.05, 0.09), h * 0.95, -0.02),
                          r * 0.6))
    return Shape("faucet", parts)


def guitar(rng: np.random.Generator) -> Shape:
    lb = rng.uniform(0.17, 0.21)
    ub = lb * rng.uniform(0.7, 0.85)
    t = rng.uniform(0.05, 0.1)
    parts = [ellipsoid((0, lb, 0), (lb, lb * 1.05, t / 2)), ellipsoid((0, 2 * lb + ub * 0.6, 0), (ub, ub, t / 2))]
    nl = rng.uniform(0.4, 0.5)
    y0 = 2 * lb + ub * 1.4
    parts.append(box((0, y0 + nl / 2 - 0.05, t * 0.2), (0.05, nl, 0.025)))
    parts.append(box((0, y0 + nl - 0.05 + 0.08, t * 0.15), (0.08, 0.17, 0.02), rot_x(rng.uniform(0, 12))))
    parts.append(box((0, lb * 0.6, t / 2), (0.1, 0.02, 0.012)))  # bridge
    return Shape("guitar", parts)


def firearm(rng: np.random.Generator) -> Shape:
    rl = rng.uniform(0.25, 0.4)
    rh = rng.uniform(0.06, 0.1)
    bl = rng.uniform(0.3, 0.6)
    parts = [box((0, 0, 0), (0.05, rh, rl))]
    parts.append(cylinder((0, rh * 0.2, rl / 2), (0, rh * 0.2, rl / 2 + bl), rng.uniform(0.01, 0.018)))
    if rng.random() < 0.7:  # fore-end
        parts.append(box((0, -rh * 0.2, rl / 2 + bl * 0.25), (0.045, rh * 0.6, bl * 0.45)))
    sl = rng.uniform(0.25, 0.35)
    parts.append(Primitive("box", (0.045, rh * 1.2, sl),
                           pose((0, -rh * 0.4, -rl / 2 - sl / 2 + 0.02), rot_x(-rng.uniform(5, 15)))))
    parts.append(Primitive("box", (0.04, 0.12, 0.04), pose((0, -rh / 2 - 0.05, -rl * 0.25), rot_x(-20))))
    if rng.random() < 0.7:
        parts.append(Primitive("box", (0.03, rng.uniform(0.1, 0.18), 0.05), pose((0, -rh / 2 - 0.07, rl * 0.15), rot_x(10))))
    if rng.random() < 0.5:  # scope
        parts.append(cylinder((0, rh / 2 + 0.03, -rl * 0.3), (0, rh / 2 + 0.03, rl * 0.35), 0.02))
    return Shape("firearm", parts)


def plane(rng: np.random.Generator) -> Shape:
    L = rng.uniform(3.0, 4.0)
    fr = L * rng.uniform(0.05, 0.07)
    parts = [ellipsoid((0, 0, 0), (fr, fr, L / 2))]
    span = L * rng.uniform(0.8, 1.2)
    chord = L * rng.uniform(0.12, 0.2)
    wz = L * rng.uniform(-0.05, 0.1)
    sweep = rng.uniform(0, 25)
    for sx in (-1, 1):
        parts.append(Primitive("box", (span / 2, 0.04 * L / 3, chord),
                               pose((sx * span / 4, -fr * 0.3, wz - span / 4 * np.tan(np.radians(sweep))), rot_y(sx * sweep))))
        if rng.random() < 0.7:  # engines
            parts.append(cylinder((sx * span * 0.2, -fr * 0.9, wz + chord * 0.4), (sx * span * 0.2, -fr * 0.9, wz - chord * 0.5),
                                  fr * 0.4))
    parts.append(box((0, fr * 1.4, -L / 2 + chord * 0.35), (0.03 * L / 3, fr * 2.2, chord * 0.6)))
    parts.append(box((0, fr * 0.2, -L / 2 + chord * 0.3), (span * 0.35, 0.03 * L / 3, chord * 0.45)))
    return Shape("plane", parts)
