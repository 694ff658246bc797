"""Procedural ShapeNet-like shapes built from analytic primitives.

A shape is a list of :class:`Primitive` (box, cylinder, ellipsoid, torus), each
with a 4x4 transform from its local frame to the object frame. Object frame:
y is up, the floor is y = 0, x is the width and +z the front of the object.

Two views of the same shape are exact and consistent:
- :meth:`Primitive.inside` is the analytic inside test (used for the solid
  occupancy target, evaluated at voxel centres);
- :meth:`Primitive.mesh` / :func:`shape_mesh` give a trimesh (used only to
  render the depth image).

Seen categories (training): bench, chair, couch, table, each assembled from
parts with random proportions and styles. Unseen categories (test only): car,
faucet, firearm, guitar, monitor, plane.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

SEEN_CATEGORIES = ("bench", "chair", "couch", "table")
UNSEEN_CATEGORIES = ("car", "faucet", "firearm", "guitar", "monitor", "plane")
KINDS = ("box", "cylinder", "ellipsoid", "torus")


@dataclass
class Primitive:
    """One analytic solid.

    ``size`` by kind (all in the local frame):
      box: full extents (ex, ey, ez), centred at the origin;
      cylinder: (radius, height), axis along local z, centred;
      ellipsoid: radii (rx, ry, rz);
      torus: (major, minor), axis along local z.
    ``transform``: (4, 4) float64 local -> object frame (rotation + translation).
    """

    kind: str
    size: tuple[float, ...]
    transform: np.ndarray = field(default_factory=lambda: np.eye(4))

    def inside(self, x, y, z, pad: float = 0.0):
        """Local coordinates (arrays of one broadcastable shape) -> bool array, True inside.

        ``pad`` (local units) grows the solid by about that distance (exact for boxes
        and cylinders, approximate for ellipsoids); used for conservative voxelisation.
        """
        s = self.size
        if self.kind == "box":
            return (np.abs(x) <= s[0] / 2 + pad) & (np.abs(y) <= s[1] / 2 + pad) & (np.abs(z) <= s[2] / 2 + pad)
        if self.kind == "cylinder":
            return (x * x + y * y <= (s[0] + pad) ** 2) & (np.abs(z) <= s[1] / 2 + pad)
        if self.kind == "ellipsoid":
            return (x / (s[0] + pad)) ** 2 + (y / (s[1] + pad)) ** 2 + (z / (s[2] + pad)) ** 2 <= 1.0
        if self.kind == "torus":
            return (np.sqrt(x * x + y * y) - s[0]) ** 2 + z * z <= (s[1] + pad) ** 2
        raise ValueError(f"unknown primitive kind {self.kind!r}")

    def contains(self, points: np.ndarray, pad: float = 0.0) -> np.ndarray:
        """(N, 3) object-frame points -> (N,) bool (inside or on the surface)."""
        inv = np.linalg.inv(self.transform)
        local = points @ inv[:3, :3].T + inv[:3, 3]
        return self.inside(local[:, 0], local[:, 1], local[:, 2], pad)

    def local_bounds(self) -> np.ndarray:
        """(2, 3) min/max corners of the local axis-aligned bounding box."""
        s = self.size
        if self.kind == "box":
            h = np.asarray(s, float) / 2
        elif self.kind == "cylinder":
            h = np.array([s[0], s[0], s[1] / 2])
        elif self.kind == "ellipsoid":
            h = np.asarray(s, float)
        else:
            h = np.array([s[0] + s[1], s[0] + s[1], s[1]])
        return np.stack([-h, h])

    def corners(self) -> np.ndarray:
        """(8, 3) corners of the local bounding box in the object frame."""
        lo, hi = self.local_bounds()
        c = np.array([[a, b, d] for a in (lo[0], hi[0]) for b in (lo[1], hi[1]) for d in (lo[2], hi[2])])
        return c @ self.transform[:3, :3].T + self.transform[:3, 3]

    def mesh(self):
        """A trimesh of the primitive in the object frame (render only)."""
        import trimesh  # noqa: PLC0415

        s = self.size
        if self.kind == "box":
            m = trimesh.creation.box(extents=s)
        elif self.kind == "cylinder":
            m = trimesh.creation.cylinder(radius=s[0], height=s[1], sections=24)
        elif self.kind == "ellipsoid":
            m = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
            m.apply_scale(np.asarray(s, float))
        elif self.kind == "torus":
            m = trimesh.creation.torus(major_radius=s[0], minor_radius=s[1], major_sections=32, minor_sections=12)
        else:
            raise ValueError(f"unknown primitive kind {self.kind!r}")
        m.apply_transform(self.transform)
        return m


@dataclass
class Shape:
    """A category name and its primitives (object frame, y up)."""

    category: str
    primitives: list[Primitive]

    def vertices(self) -> np.ndarray:
        """(N, 3) mesh vertices of all primitives (object frame)."""
        return np.concatenate([p.mesh().vertices for p in self.primitives])

    def contains(self, points: np.ndarray, pad: float = 0.0) -> np.ndarray:
        """(N, 3) object-frame points -> (N,) bool: inside the union of the primitives."""
        out = np.zeros(len(points), dtype=bool)
        for p in self.primitives:
            out |= p.contains(points, pad)
        return out


def shape_mesh(shape: Shape):
    """All primitive meshes concatenated into one trimesh (overlaps are fine for rendering)."""
    import trimesh  # noqa: PLC0415

    return trimesh.util.concatenate([p.mesh() for p in shape.primitives])


# ---------------------------------------------------------------- transforms
def rot_x(deg: float) -> np.ndarray:
    a = np.radians(deg)
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def rot_y(deg: float) -> np.ndarray:
    a = np.radians(deg)
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def rot_z(deg: float) -> np.ndarray:
    a = np.radians(deg)
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def _tf(center, rot=None) -> np.ndarray:
    t = np.eye(4)
    if rot is not None:
        t[:3, :3] = rot
    t[:3, 3] = center
    return t


def box(center, extents, rot=None) -> Primitive:
    return Primitive("box", tuple(float(e) for e in extents), _tf(center, rot))


def ellipsoid(center, radii, rot=None) -> Primitive:
    return Primitive("ellipsoid", tuple(float(r) for r in radii), _tf(center, rot))


def torus(center, major, minor, rot=None) -> Primitive:
    return Primitive("torus", (float(major), float(minor)), _tf(center, rot))


def _align_z(d: np.ndarray) -> np.ndarray:
    """Rotation taking local +z onto the unit vector ``d``."""
    z = np.array([0.0, 0.0, 1.0])
    v = np.cross(z, d)
    c = float(np.dot(z, d))
    if np.linalg.norm(v) < 1e-9:
        return np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    vx = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + vx + vx @ vx / (1 + c)


def cylinder(p0, p1, radius) -> Primitive:
    """Cylinder of ``radius`` whose axis runs from point ``p0`` to ``p1``."""
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    d = p1 - p0
    h = float(np.linalg.norm(d))
    return Primitive("cylinder", (float(radius), h), _tf((p0 + p1) / 2, _align_z(d / h)))


def beam(p0, p1, thick_x, thick_z) -> Primitive:
    """A box from ``p0`` to ``p1`` (mostly vertical parts such as legs and posts)."""
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    d = p1 - p0
    h = float(np.linalg.norm(d))
    return Primitive("box", (float(thick_x), float(thick_z), h), _tf((p0 + p1) / 2, _align_z(d / h)))


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
                parts.append(Primitive("box", (arm, 0.04, 0.05), _tf(dirv * arm / 2 + [0, 0.03, 0], rot_y(a))))
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
        parts.append(Primitive("box", (w, hb, t), _tf(at((0, hb / 2, 0)), rot)))
    else:  # slatted: two posts, a top rail, vertical or horizontal slats
        post = t * 1.2
        for sx in (-1, 1):
            parts.append(Primitive("box", (post, hb, t), _tf(at((sx * (w / 2 - post / 2), hb / 2, 0)), rot)))
        rail = hb * rng.uniform(0.12, 0.25)
        parts.append(Primitive("box", (w, rail, t), _tf(at((0, hb - rail / 2, 0)), rot)))
        inner = w - 2 * post
        if rng.random() < 0.5:
            n = int(rng.integers(2, 6))
            sw = inner / (2 * n + 1)
            for k in range(n):
                x = -inner / 2 + sw * (2 * k + 1.5)
                parts.append(Primitive("box", (sw, hb - rail, t * 0.7), _tf(at((x, (hb - rail) / 2, 0)), rot)))
        else:
            n = int(rng.integers(1, 4))
            for k in range(n):
                y = (hb - rail) * (k + 1) / (n + 1)
                parts.append(Primitive("box", (inner, rail * 0.6, t * 0.7), _tf(at((0, y, 0)), rot)))
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
        parts = [Primitive("cylinder", (w / 2, t), _tf((0, h + t / 2, 0), rot_x(90)))]
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
    parts += _legs(rng, str(rng.choice(["four", "panel", "sled"])), w, d, h, rng.uniform(0.04, 0.07), inset=w * rng.uniform(0, 0.08))
    if rng.random() < 0.5:
        bt = 0.04
        parts += _back(rng, str(rng.choice(["solid", "slatted"])), w, h + t, rng.uniform(0.25, 0.45), -d / 2 + bt / 2, bt, rng.uniform(0, 12))
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
            parts.append(Primitive("cylinder", (arm_w / 2, d), _tf((x, top + arm_h - arm_w / 2, 0))))
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


# ---------------------------------------------------------------- unseen categories
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
                parts.append(Primitive("cylinder", (r, 0.24), _tf(c, rot_y(90))))
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
        parts.append(Primitive("cylinder", (rng.uniform(0.1, 0.15), 0.02), _tf((0, 0.01, -st), rot_x(90))))
    else:
        parts.append(box((0, 0.01, -st), (rng.uniform(0.2, 0.3), 0.02, rng.uniform(0.12, 0.2))))
    return Shape("monitor", parts)


def faucet(rng: np.random.Generator) -> Shape:
    h = rng.uniform(0.15, 0.3)
    r = rng.uniform(0.015, 0.025)
    reach = rng.uniform(0.1, 0.2)
    parts = [Primitive("cylinder", (r * 2.2, 0.02), _tf((0, 0.01, 0), rot_x(90)))]
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
    parts.append(cylinder((0, h * rng.uniform(0.6, 0.9), 0), (rng.choice([-1, 1]) * rng.uniform(0.05, 0.09), h * 0.95, -0.02), r * 0.6))
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
    parts.append(Primitive("box", (0.045, rh * 1.2, sl), _tf((0, -rh * 0.4, -rl / 2 - sl / 2 + 0.02), rot_x(-rng.uniform(5, 15)))))
    parts.append(Primitive("box", (0.04, 0.12, 0.04), _tf((0, -rh / 2 - 0.05, -rl * 0.25), rot_x(-20))))
    if rng.random() < 0.7:
        parts.append(Primitive("box", (0.03, rng.uniform(0.1, 0.18), 0.05), _tf((0, -rh / 2 - 0.07, rl * 0.15), rot_x(10))))
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
                               _tf((sx * span / 4, -fr * 0.3, wz - span / 4 * np.tan(np.radians(sweep))), rot_y(sx * sweep))))
        if rng.random() < 0.7:  # engines
            parts.append(cylinder((sx * span * 0.2, -fr * 0.9, wz + chord * 0.4), (sx * span * 0.2, -fr * 0.9, wz - chord * 0.5), fr * 0.4))
    parts.append(box((0, fr * 1.4, -L / 2 + chord * 0.35), (0.03 * L / 3, fr * 2.2, chord * 0.6)))
    parts.append(box((0, fr * 0.2, -L / 2 + chord * 0.3), (span * 0.35, 0.03 * L / 3, chord * 0.45)))
    return Shape("plane", parts)


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
