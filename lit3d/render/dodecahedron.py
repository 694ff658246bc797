"""The 12 view directions of the quality task and their camera poses (:func:`lit3d.render.camera.look_at`).

The thesis places 12 cameras at the face centres of a regular dodecahedron, all
looking at the shape's centre. The face centres of a dodecahedron point in the
same directions as the 12 vertices of its dual, the icosahedron:
``(0, ±1, ±φ), (±1, ±φ, 0), (±φ, 0, ±1)`` with ``φ = (1 + √5) / 2``. Normalised,
any two directions are either antipodal or meet at ``arccos(±1/√5)``
(63.43° or 116.57°).
"""
from __future__ import annotations

import math

import numpy as np

from lit3d.render.camera import look_at

PHI = (1.0 + math.sqrt(5.0)) / 2.0
N_VIEWS = 12


def dodecahedron_directions() -> np.ndarray:
    """The 12 unit view directions, ``(12, 3) float64``, origin -> camera.

    Exact up to float64 rounding: icosahedron vertices divided by ``sqrt(1 + φ²)``.
    Ordered as ``(0, ±1, ±φ)``, ``(±1, ±φ, 0)``, ``(±φ, 0, ±1)``.
    """
    dirs = []
    for s1 in (1.0, -1.0):
        for s2 in (1.0, -1.0):
            dirs.append((0.0, s1, s2 * PHI))
    for s1 in (1.0, -1.0):
        for s2 in (1.0, -1.0):
            dirs.append((s1, s2 * PHI, 0.0))
    for s1 in (1.0, -1.0):
        for s2 in (1.0, -1.0):
            dirs.append((s1 * PHI, 0.0, s2))
    d = np.asarray(dirs, dtype=np.float64)
    return d / math.sqrt(1.0 + PHI * PHI)


def camera_poses(distance: float = 3.0, directions: np.ndarray | None = None) -> np.ndarray:
    """Camera-to-world poses ``(V, 4, 4) float64`` at ``distance`` along each direction.

    Defaults to the 12 dodecahedron directions; every camera looks at the origin.
    """
    dirs = dodecahedron_directions() if directions is None else np.asarray(directions, dtype=np.float64)
    return np.stack([look_at(d * distance) for d in dirs])
