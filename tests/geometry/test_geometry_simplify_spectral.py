"""The one simplifier (lit3d.geometry.simplify) and the potpourri3d cotangent Laplacian."""
from __future__ import annotations

import numpy as np
import pytest
import trimesh

from lit3d.geometry.simplify import simplify, simplify_to_vertices
from lit3d.geometry.spectral import cotangent_laplacian


def test_simplify_matches_trimesh_quadric_decimation():
    m = trimesh.creation.icosphere(subdivisions=4)
    v, f = simplify(m.vertices, m.faces, 1000)
    ref = m.simplify_quadric_decimation(face_count=1000)  # trimesh's own fast_simplification wrapper
    assert abs(len(f) - 1000) <= 10 and v.dtype == np.float64 and f.dtype == np.int64
    np.testing.assert_allclose(v, ref.vertices)
    np.testing.assert_array_equal(f, ref.faces)


def _open_grid(n: int = 30) -> trimesh.Trimesh:
    """An open height-field surface (like a back-projected depth image): n x n vertices."""
    x, y = np.meshgrid(np.linspace(-1, 1, n), np.linspace(-1, 1, n))
    v = np.stack([x, y, 0.2 * np.sin(3 * x) * np.cos(2 * y)], -1).reshape(-1, 3)
    i = np.arange(n * n).reshape(n, n)
    a, b, c, d = i[:-1, :-1].ravel(), i[:-1, 1:].ravel(), i[1:, :-1].ravel(), i[1:, 1:].ravel()
    return trimesh.Trimesh(v, np.concatenate([np.stack([a, c, b], 1), np.stack([b, c, d], 1)]), process=False)


@pytest.mark.parametrize("mesh", [trimesh.creation.icosphere(subdivisions=4), _open_grid(),
                                  trimesh.creation.torus(0.7, 0.25, 64, 32)], ids=["sphere", "open", "torus"])
def test_simplify_to_vertices_meets_the_budget(mesh):
    v, f = simplify_to_vertices(mesh.vertices, mesh.faces, 300)
    assert 150 < len(v) <= 300 and f.max() == len(v) - 1 and len(np.unique(f)) == len(v)
    assert simplify_to_vertices(v, f, 300)[0] is v  # already within budget: unchanged


def test_simplify_to_vertices_returns_the_smallest_when_decimation_stalls(caplog):
    ring = trimesh.creation.annulus(0.2, 0.5, 0.3, sections=96)  # sliver triangles: the decimator keeps all
    v, f = simplify_to_vertices(ring.vertices, ring.faces, 300)
    assert len(v) <= len(ring.vertices) and "stalled" in caplog.text


def _reference_cotangent(verts, faces):
    """Textbook cotangent weights from the triangle angles: L_ij = -(cot a + cot b) / 2."""
    n = len(verts)
    L = np.zeros((n, n))
    area = np.zeros(n)
    for tri in faces:
        p = verts[tri]
        for k in range(3):
            i, j, o = tri[k], tri[(k + 1) % 3], tri[(k + 2) % 3]
            a, b = verts[i] - verts[o], verts[j] - verts[o]
            angle = np.arccos(np.clip(a @ b / np.linalg.norm(a) / np.linalg.norm(b), -1, 1))
            w = 0.5 / np.tan(angle)
            L[i, j] -= w
            L[j, i] -= w
        area[tri] += 0.5 * np.linalg.norm(np.cross(p[1] - p[0], p[2] - p[0])) / 3
    L[np.diag_indices(n)] = -L.sum(1)
    return L, area


@pytest.mark.parametrize("mesh", [trimesh.creation.icosphere(subdivisions=1),
                                  trimesh.creation.annulus(0.2, 0.5, 0.3, sections=8)], ids=["closed", "open"])
def test_cotangent_laplacian_matches_the_textbook_formula(mesh):
    v = np.asarray(mesh.vertices) * [1.7, 1.0, 0.8]
    L, area = cotangent_laplacian(v, mesh.faces)
    L_ref, area_ref = _reference_cotangent(v, np.asarray(mesh.faces))
    np.testing.assert_allclose(L.toarray(), L_ref, atol=1e-9)
    np.testing.assert_allclose(area, area_ref, atol=1e-12)
    assert area.sum() == pytest.approx(trimesh.Trimesh(v, mesh.faces).area)
