"""Chamfer / Hausdorff on surface samples against brute force and known geometry."""
from __future__ import annotations

import numpy as np
import trimesh
from scipy.spatial.distance import cdist

from lit3d.metrics.mesh import chamfer_hausdorff, directed_distances, surface_samples


def test_directed_distances_brute_force():
    g = np.random.default_rng(0)
    a, b = g.random((300, 3)), g.random((200, 3))
    assert np.allclose(directed_distances(a, b), cdist(a, b).min(1))


def test_identical_and_scaled_spheres():
    s = trimesh.creation.icosphere(4)
    same = chamfer_hausdorff(s, s.copy(), n=5000)
    assert same["chamfer"] < 0.02 and same["hausdorff"] < 0.06  # sampling noise only
    # normalisation makes scale irrelevant
    big = s.copy()
    big.apply_scale(7.0)
    assert chamfer_hausdorff(s, big, n=5000)["chamfer"] < 0.02


def test_distances_grow_with_noise():
    s = trimesh.creation.icosphere(4)
    g = np.random.default_rng(1)
    vals = []
    for sigma in (0.0, 0.01, 0.03):
        d = s.copy()
        d.vertices = d.vertices + d.vertex_normals * g.normal(0, sigma, (len(d.vertices), 1))
        vals.append(chamfer_hausdorff(s, d, n=5000))
    assert vals[0]["chamfer"] < vals[1]["chamfer"] < vals[2]["chamfer"]
    assert vals[0]["hausdorff"] < vals[2]["hausdorff"]


def test_samples_are_normalised():
    box = trimesh.creation.box((2.0, 4.0, 1.0))
    box.apply_translation((5, 5, 5))
    p = surface_samples(box, 2000)
    assert np.allclose(p.max(0) - p.min(0), [0.5, 1.0, 0.25], atol=1e-6)
    assert np.allclose((p.max(0) + p.min(0)) / 2, 0.0, atol=1e-6)
