"""Geometric distortions for the synthetic quality dataset (the ones the human-rated sets use).

Every function takes a ``trimesh.Trimesh`` and returns a new mesh (the input is not
modified). Amplitudes are fractions of the mesh's bounding-box diagonal, so a level
means the same thing on any shape. Random distortions take a ``seed`` and are
deterministic for it.

- :func:`normal_noise`: each vertex moves along its vertex normal by U(-a, a)
  (LIRIS/EPFL, Masking, Guo 2016 noise). Face order is kept (``trimesh.permutate.noise``
  reorders faces and moves vertices in random directions, so it is not used).
- :func:`taubin_smooth`: Taubin lambda/mu smoothing (Guo 2016), ``nu = 0.53``:
  trimesh's default ``nu = 0.5`` breaks the filter's own stability condition
  (``nu > lamb``), which shrinks the shape instead of smoothing it.
- :func:`simplify`: quadric edge-collapse decimation (``fast_simplification``, through
  :func:`lit3d.geometry.simplify.simplify`) to a fraction of the faces.
- :func:`quantize`: vertex coordinates snapped to a ``2**bits`` grid over the bounding box.
- :func:`region_noise`: normal noise only on the smooth or only on the rough part of
  the surface (LIRIS Masking), split at a roughness quantile (:func:`roughness`).

:data:`LEVELS` lists the default levels per distortion type, mildest first; the
ordinal severity of level ``k`` (0-based) of ``L`` levels is ``(k + 1) / L``.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import trimesh

from lit3d.geometry.simplify import simplify as simplify_mesh

# mildest first. noise*: amplitude / bbox diagonal; taubin: iterations; simplify: kept
# face fraction; quantize: bits per coordinate.
LEVELS: dict[str, list[float]] = {
    "noise": [0.002, 0.004, 0.008, 0.016],
    "taubin": [3, 10, 30, 90],
    "simplify": [0.5, 0.25, 0.12, 0.06],
    "quantize": [9, 8, 7, 6],
    "noise_smooth": [0.002, 0.004, 0.008, 0.016],
    "noise_rough": [0.002, 0.004, 0.008, 0.016],
}
DISTORTIONS = tuple(LEVELS)


def _diag(mesh: trimesh.Trimesh) -> float:
    ext = np.ptp(mesh.vertices, axis=0) if len(mesh.vertices) else np.zeros(3)
    d = float(np.linalg.norm(ext))
    if d <= 0:
        raise ValueError("mesh has no extent (empty or all vertices equal)")
    return d


def _copy(mesh: trimesh.Trimesh, vertices: np.ndarray) -> trimesh.Trimesh:
    return trimesh.Trimesh(vertices=np.asarray(vertices, dtype=np.float64), faces=mesh.faces.copy(), process=False)


def normal_noise(mesh: trimesh.Trimesh, amplitude: float, seed: int = 0,
                 vertex_mask: np.ndarray | None = None) -> trimesh.Trimesh:
    """Move vertices along their normals by U(-a, a), a = ``amplitude`` x bbox diagonal.

    vertex_mask: (V,) bool, only these vertices move (others keep their position).
    """
    rng = np.random.default_rng(seed)
    a = float(amplitude) * _diag(mesh)
    offsets = rng.uniform(-a, a, size=len(mesh.vertices))
    if vertex_mask is not None:
        offsets = offsets * np.asarray(vertex_mask, dtype=np.float64)
    normals = np.asarray(mesh.vertex_normals, dtype=np.float64)
    return _copy(mesh, mesh.vertices + normals * offsets[:, None])


def taubin_smooth(mesh: trimesh.Trimesh, iterations: int, lamb: float = 0.5, nu: float = 0.53) -> trimesh.Trimesh:
    """Taubin smoothing: ``iterations`` (shrink lambda, inflate mu) pairs; needs ``nu > lamb``.

    trimesh's ``filter_taubin`` counts half-steps (even index = shrink, odd = inflate), so an
    odd count there ends on a shrink; it is called with ``2 * iterations``.
    """
    out = _copy(mesh, mesh.vertices.copy())
    trimesh.smoothing.filter_taubin(out, lamb=lamb, nu=nu, iterations=2 * int(iterations))
    return out


def simplify(mesh: trimesh.Trimesh, keep_fraction: float) -> trimesh.Trimesh:
    """Keep about ``keep_fraction`` of the faces (quadric decimation, :func:`lit3d.geometry.simplify.simplify`)."""
    if not 0 < keep_fraction <= 1:
        raise ValueError(f"keep_fraction must be in (0, 1], got {keep_fraction}")
    target = max(int(round(len(mesh.faces) * keep_fraction)), 4)
    v, f = simplify_mesh(mesh.vertices, mesh.faces, target)
    out = trimesh.Trimesh(v, f)  # merges coincident vertices, as trimesh's own decimation wrapper does
    return trimesh.Trimesh(out.vertices, out.faces, process=False)


def quantize(mesh: trimesh.Trimesh, bits: int) -> trimesh.Trimesh:
    """Snap each coordinate to the nearest of ``2**bits`` levels spanning the bounding box."""
    v = mesh.vertices
    lo, ext = v.min(0), np.maximum(np.ptp(v, axis=0), 1e-12)
    step = ext.max() / (2 ** int(bits) - 1)  # one grid step for all axes (cubic cells)
    return _copy(mesh, lo + np.round((v - lo) / step) * step)


def _vertex_neighbours_mean(mesh: trimesh.Trimesh, values: np.ndarray) -> np.ndarray:
    """Mean of ``values`` over each vertex's 1-ring (itself included)."""
    edges = mesh.edges_unique
    n = len(mesh.vertices)
    acc = np.asarray(values, dtype=np.float64).copy()
    cnt = np.ones(n)
    np.add.at(acc, edges[:, 0], values[edges[:, 1]])
    np.add.at(acc, edges[:, 1], values[edges[:, 0]])
    np.add.at(cnt, edges.reshape(-1), 1.0)
    return acc / cnt


def roughness(mesh: trimesh.Trimesh, rings: int = 2) -> np.ndarray:
    """(V,) float64 per-vertex roughness: local variation of the umbrella Laplacian.

    |v - mean(1-ring)| / mean 1-ring edge length (a scale-free curvature proxy), then
    its absolute deviation from the local mean, averaged over ``rings`` rings. Flat or
    evenly curved areas score low, bumpy areas high (Lavoué's roughness, simplified).
    """
    v = mesh.vertices
    n = len(v)
    edges = mesh.edges_unique
    nb_sum = np.zeros((n, 3))
    deg = np.zeros(n)
    np.add.at(nb_sum, edges[:, 0], v[edges[:, 1]])
    np.add.at(nb_sum, edges[:, 1], v[edges[:, 0]])
    np.add.at(deg, edges.reshape(-1), 1.0)
    deg = np.maximum(deg, 1.0)
    lengths = mesh.edges_unique_length
    elen = np.zeros(n)
    np.add.at(elen, edges[:, 0], lengths)
    np.add.at(elen, edges[:, 1], lengths)
    elen = np.maximum(elen / deg, 1e-12)
    lap = np.linalg.norm(v - nb_sum / deg[:, None], axis=1) / elen
    local = lap.copy()
    for _ in range(rings):
        local = _vertex_neighbours_mean(mesh, local)
    rough = np.abs(lap - local)
    for _ in range(rings):
        rough = _vertex_neighbours_mean(mesh, rough)
    return rough


def region_mask(mesh: trimesh.Trimesh, region: str, quantile: float = 0.5) -> np.ndarray:
    """(V,) bool: vertices whose roughness is below ("smooth") / above ("rough") the quantile."""
    r = roughness(mesh)
    cut = np.quantile(r, quantile)
    if region == "smooth":
        return r <= cut
    if region == "rough":
        return r > cut
    raise ValueError(f"unknown region '{region}' (smooth | rough)")


def region_noise(mesh: trimesh.Trimesh, amplitude: float, region: str, seed: int = 0,
                 quantile: float = 0.5) -> trimesh.Trimesh:
    """Normal-direction noise on the smooth or on the rough vertices only (LIRIS Masking)."""
    return normal_noise(mesh, amplitude, seed, vertex_mask=region_mask(mesh, region, quantile))


def n_levels(kind: str, levels: Mapping[str, Sequence[float]] | None = None) -> int:
    return len((levels or LEVELS)[kind])


def severity(kind: str, level: int, levels: Mapping[str, Sequence[float]] | None = None) -> float:
    """Ordinal severity score of ``level`` (0-based, mildest first): ``(level + 1) / n_levels``.

    An ordinal rank within one distortion type, scaled to (0, 1]: NOT a human opinion score.
    """
    n = n_levels(kind, levels)
    if not 0 <= level < n:
        raise IndexError(f"{kind}: level {level} out of range 0..{n - 1}")
    return (level + 1) / n


def distort(mesh: trimesh.Trimesh, kind: str, level: int, seed: int = 0,
            levels: Mapping[str, Sequence[float]] | None = None) -> trimesh.Trimesh:
    """Apply level ``level`` (0-based, mildest first) of distortion ``kind``."""
    table = levels or LEVELS
    if kind not in table:
        raise KeyError(f"unknown distortion '{kind}' (known: {', '.join(table)})")
    values = list(table[kind])
    if not 0 <= level < len(values):
        raise IndexError(f"{kind}: level {level} out of range 0..{len(values) - 1}")
    p = values[level]
    if kind == "noise":
        return normal_noise(mesh, p, seed)
    if kind == "taubin":
        return taubin_smooth(mesh, int(p))
    if kind == "simplify":
        return simplify(mesh, float(p))
    if kind == "quantize":
        return quantize(mesh, int(p))
    if kind in ("noise_smooth", "noise_rough"):
        return region_noise(mesh, p, kind.split("_")[1], seed)
    raise KeyError(f"no implementation for distortion '{kind}'")
