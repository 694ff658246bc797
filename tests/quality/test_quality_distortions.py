"""Distortions of the synthetic quality set: direction, monotone strength, determinism."""
from __future__ import annotations

import numpy as np
import pytest
import trimesh
from scipy.spatial import cKDTree

from datamodules.quality import PROCEDURAL_SHAPES, procedural_shape
from datamodules.quality.distortions import (
    LEVELS,
    distort,
    normal_noise,
    quantize,
    region_mask,
    severity,
    simplify,
    taubin_smooth,
)


@pytest.fixture(scope="module")
def bumpy():
    return procedural_shape("bumpy", subdivisions=3)


def _dist(a: trimesh.Trimesh, b: trimesh.Trimesh) -> float:
    return float(cKDTree(a.vertices).query(b.vertices)[0].mean())


def test_procedural_shapes_are_valid():
    for name in PROCEDURAL_SHAPES:
        m = procedural_shape(name, subdivisions=2)
        assert len(m.faces) > 100 and np.isfinite(m.vertices).all(), name


def test_normal_noise_moves_along_normals_keeps_faces(bumpy):
    out = normal_noise(bumpy, 0.01, seed=3)
    np.testing.assert_array_equal(out.faces, bumpy.faces)
    d = out.vertices - bumpy.vertices
    n = bumpy.vertex_normals
    along = (d * n).sum(1)
    np.testing.assert_allclose(d, n * along[:, None], atol=1e-12)  # purely normal direction
    diag = np.linalg.norm(np.ptp(bumpy.vertices, axis=0))
    assert np.abs(along).max() <= 0.01 * diag + 1e-12
    np.testing.assert_array_equal(normal_noise(bumpy, 0.01, seed=3).vertices, out.vertices)  # deterministic
    assert not np.array_equal(normal_noise(bumpy, 0.01, seed=4).vertices, out.vertices)


def test_taubin_smooths_without_shrinking(bumpy):
    out = taubin_smooth(bumpy, 20)
    vol0, vol1 = bumpy.volume, out.volume
    assert abs(vol1 - vol0) / vol0 < 0.05  # nu=0.53 > lambda: no shrinking

    def lap(m):
        return np.linalg.norm(m.vertices - np.array([m.vertices[list(nb)].mean(0) for nb in m.vertex_neighbors]), axis=1).mean()

    assert lap(out) < 0.7 * lap(bumpy)


def test_simplify_and_quantize(bumpy):
    s = simplify(bumpy, 0.25)
    assert abs(len(s.faces) - 0.25 * len(bumpy.faces)) < 0.05 * len(bumpy.faces)
    assert len(s.vertices) < 0.5 * len(bumpy.vertices)  # (was: the removed vertex-clustering method)
    q = quantize(bumpy, 5)
    step = np.ptp(bumpy.vertices, axis=0).max() / 31
    k = (q.vertices - bumpy.vertices.min(0)) / step
    np.testing.assert_allclose(k, np.round(k), atol=1e-6)


def test_region_noise_touches_only_its_region(bumpy):
    rough = region_mask(bumpy, "rough")
    assert 0.3 < rough.mean() < 0.7
    # the bumps are on the upper hemisphere: the rough region should be mostly there
    assert (bumpy.vertices[rough, 2] > 0).mean() > 0.7
    out = distort(bumpy, "noise_smooth", 3, seed=1)
    moved = np.linalg.norm(out.vertices - bumpy.vertices, axis=1) > 0
    assert not moved[rough].any() and moved[~rough].any()


@pytest.mark.parametrize("kind", ["noise", "taubin", "simplify", "quantize", "noise_rough"])
def test_levels_get_stronger(bumpy, kind):
    outs = [distort(bumpy, kind, k, seed=0) for k in range(len(LEVELS[kind]))]
    if kind == "simplify":  # new vertices: distance to the nearest reference vertex
        d = [_dist(bumpy, o) for o in outs]
    else:  # same vertices: mean displacement
        d = [float(np.linalg.norm(o.vertices - bumpy.vertices, axis=1).mean()) for o in outs]
    assert all(b > a for a, b in zip(d, d[1:])), d
    assert severity(kind, 0) == 1 / len(LEVELS[kind]) and severity(kind, len(LEVELS[kind]) - 1) == 1.0


def _split_obj(mesh: trimesh.Trimesh) -> str:
    """OBJ text of ``mesh`` with one normal per face (``f a//n``): trimesh loads every corner as
    its own vertex, as it does the Stanford bunny's per-corner normals."""
    lines = [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in mesh.vertices]
    lines += [f"vn {x:.6f} {y:.6f} {z:.6f}" for x, y, z in mesh.face_normals]
    lines += ["f " + " ".join(f"{a + 1}//{i + 1}" for a in face) for i, face in enumerate(mesh.faces)]
    return "\n".join(lines) + "\n"


def test_user_meshes_are_merged_by_position(tmp_path):
    from datamodules.quality.quality_shapes import load_user_meshes

    cube = trimesh.creation.box()
    (tmp_path / "cube.obj").write_text(_split_obj(cube))
    raw = trimesh.load(tmp_path / "cube.obj", force="mesh", process=False)
    assert len(raw.vertices) == 3 * len(cube.faces) and not raw.is_watertight  # split by the loader
    m = load_user_meshes(tmp_path)["cube"]
    assert len(m.vertices) == len(np.unique(cube.vertices, axis=0)) == 8
    assert len(m.faces) == 12 and m.is_watertight
    np.testing.assert_allclose(m.volume, cube.volume, atol=1e-5)
    # a per-vertex distortion keeps the surface closed (no seams along the split edges)
    assert distort(m, "noise", 2, seed=1).is_watertight


def test_user_mesh_faces_collapsed_by_merging_are_dropped(tmp_path):
    from datamodules.quality.quality_shapes import load_user_meshes

    cube = trimesh.creation.box()
    # an extra face whose first two corners are two copies of one position (vertex 1 and a copy, 9)
    x, y, z = cube.vertices[0]
    text = _split_obj(cube) + f"v {x:.6f} {y:.6f} {z:.6f}\nf 1//1 9//1 2//1\n"
    (tmp_path / "cube.obj").write_text(text)
    m = load_user_meshes(tmp_path)["cube"]
    assert len(m.vertices) == 8 and len(m.faces) == 12 and m.is_watertight
