"""The one mesh normaliser: centre on the bounding-box centre, scale to unit longest side."""
from __future__ import annotations

import numpy as np


def bounding_frame(verts: np.ndarray, scale: float | None = None) -> tuple[np.ndarray, float]:
    """``verts`` (V, 3) -> (bounding-box centre (3,), scale): ``(verts - centre) * scale`` is the
    normalised shape. The scale makes the longest bounding-box side 1 unless ``scale`` is given."""
    verts = np.asarray(verts, dtype=np.float64)
    lo, hi = verts.min(0), verts.max(0)
    return (lo + hi) / 2, scale if scale is not None else 1.0 / max(float((hi - lo).max()), 1e-12)


def normalise_vertices(verts: np.ndarray, scale: float | None = None) -> tuple[np.ndarray, float]:
    """``verts`` (V, 3) -> (centred and scaled (V, 3) float64, the scale used).

    The bounding-box centre goes to the origin; the longest bounding-box side becomes 1, or the
    vertices are multiplied by ``scale`` when given (e.g. to give every pose of a subject the scale
    of its canonical pose)."""
    centre, s = bounding_frame(verts, scale)
    return (np.asarray(verts, dtype=np.float64) - centre) * s, s
