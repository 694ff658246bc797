"""Analytic solid primitives of the procedural shapes (see :mod:`datamodules.completion.furniture`).

A shape is a list of :class:`Primitive` (box, cylinder, ellipsoid, torus), each
with a 4x4 transform from its local frame to the object frame. Object frame:
y is up, the floor is y = 0, x is the width and +z the front of the object.

Two views of the same shape are exact and consistent:
- :meth:`Primitive.inside` is the analytic inside test (used for the solid
  occupancy target, evaluated at voxel centres);
- :meth:`Primitive.mesh` / :func:`shape_mesh` give a trimesh (used only to
  render the depth image).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

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
        import trimesh

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
    import trimesh

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


def pose(center, rot=None) -> np.ndarray:
    """(4, 4) float64 local -> object frame: rotation ``rot`` (3, 3) (identity if None), then translation."""
    t = np.eye(4)
    if rot is not None:
        t[:3, :3] = rot
    t[:3, 3] = center
    return t


def box(center, extents, rot=None) -> Primitive:
    return Primitive("box", tuple(float(e) for e in extents), pose(center, rot))


def ellipsoid(center, radii, rot=None) -> Primitive:
    return Primitive("ellipsoid", tuple(float(r) for r in radii), pose(center, rot))


def torus(center, major, minor, rot=None) -> Primitive:
    return Primitive("torus", (float(major), float(minor)), pose(center, rot))


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
    return Primitive("cylinder", (float(radius), h), pose((p0 + p1) / 2, _align_z(d / h)))


def beam(p0, p1, thick_x, thick_z) -> Primitive:
    """A box from ``p0`` to ``p1`` (mostly vertical parts such as legs and posts)."""
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    d = p1 - p0
    h = float(np.linalg.norm(d))
    return Primitive("box", (float(thick_x), float(thick_z), h), pose((p0 + p1) / 2, _align_z(d / h)))
