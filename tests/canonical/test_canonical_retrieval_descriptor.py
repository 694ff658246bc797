"""CM-BOF-style descriptor (views, rotations, distances) and the MDS / GPS canonical-form baselines."""
import numpy as np
import pytest
import trimesh

from lit3d.geometry.canonical_forms import canonical_forms
from lit3d.geometry.geodesics import geodesic_matrix
from lit3d.geometry.mds import classical_mds
from lit3d.geometry.simplify import simplify_to_vertices
from lit3d.geometry.spectral import gps_embedding
from lit3d.metrics.retrieval import retrieval_scores
from lit3d.retrieval.descriptor import (
    DescriptorConfig,
    cube_rotations,
    depth_meshes,
    distance_matrix_from_depths,
    distance_matrix_from_features,
    distance_matrix_from_meshes,
    distinct,
    mesh_features,
    octahedron_views,
    shape_distances,
    view_permutations,
)


def test_views_and_rotation_group():
    assert [len(octahedron_views(k)) for k in (0, 1, 2)] == [6, 18, 66]
    R = cube_rotations()
    assert len(R) == 24 and np.allclose([np.linalg.det(r) for r in R], 1)
    dirs = octahedron_views(2)
    P = view_permutations(dirs)
    assert P.shape == (24, 66)
    assert all(sorted(p) == list(range(66)) for p in P)  # each rotation permutes the views


def test_descriptor_separates_shape_classes_and_ignores_rotation():
    rng = np.random.default_rng(0)
    meshes, labels = [], []
    for i in range(3):
        box = trimesh.creation.box(extents=(1.0, 0.5 + 0.05 * i, 0.25))
        cyl = trimesh.creation.torus(major_radius=0.5, minor_radius=0.12 + 0.01 * i) if hasattr(trimesh.creation, "torus") \
            else trimesh.creation.cylinder(radius=0.3, height=1.0)
        for m, lab in ((box, "box"), (cyl, "ring")):
            R = trimesh.transformations.random_rotation_matrix(rng.random(3))
            m = m.copy()
            m.apply_transform(R)
            meshes.append((m.vertices, m.faces))
            labels.append(lab)
    cfg = DescriptorConfig(level=1, view_size=64, vocab=48, dense_step=6)
    D = distance_matrix_from_meshes(meshes, cfg)
    assert D.shape == (6, 6) and np.allclose(D, D.T) and np.allclose(np.diag(D), 0)
    assert retrieval_scores(D, labels)["nn"] == 1.0
    # the view descriptors in 2 worker processes: the same features, in the meshes' order
    workers = mesh_features(meshes, DescriptorConfig(level=1, view_size=64, vocab=48, dense_step=6, workers=2))
    for one, two in zip(mesh_features(meshes, cfg), workers, strict=True):
        assert len(one) == len(two) == 18 and all(np.array_equal(a, b) for a, b in zip(one, two))


def test_shape_distances_against_a_loop_over_rotations_and_views():
    """Reference: for each pair, each view rotation r, the mean over views v of 1 - sum_k min(a[v, k], b[r(v), k]),
    minimised over r; the diagonal is each shape against itself only when asked."""
    rng = np.random.default_rng(3)
    hists = [rng.dirichlet(np.ones(7), size=5) * (rng.random((5, 1)) > 0.2) for _ in range(4)]  # some empty views
    cycle = rng.permutation(5)
    perms = np.stack([np.argsort(cycle)[(np.arange(5) + k) % 5][cycle] for k in range(5)])  # a group, as the rotations

    def reference(a, b):
        return min(np.mean([1 - np.minimum(a[v], b[p[v]]).sum() for v in range(5)]) for p in perms)

    want = np.array([[reference(a, b) for b in hists] for a in hists])
    np.testing.assert_allclose(shape_distances(hists, perms, diagonal=True), want, atol=1e-6)
    off = want.copy()
    np.fill_diagonal(off, 0)
    np.testing.assert_allclose(shape_distances(hists, perms), off, atol=1e-6)
    ident = np.array([[np.mean([1 - np.minimum(a[v], b[v]).sum() for v in range(5)]) for b in hists] for a in hists])
    np.fill_diagonal(ident, 0)
    np.testing.assert_allclose(shape_distances(hists, None), ident, atol=1e-6)


def test_identical_depth_images_are_described_once(monkeypatch):
    """The true canonical row repeats one image per subject: describing the distinct images once must give
    the distances of describing every image (the codebook weighs each image as often as it appears)."""
    import lit3d.retrieval.descriptor as descriptor

    yy, xx = np.mgrid[:32, :32] / 31.0 - 0.5
    blobs = []
    for a, b in ((0.35, 0.15), (0.2, 0.3), (0.3, 0.3)):
        inside = (xx / a) ** 2 + (yy / b) ** 2 < 1
        blobs.append((np.where(inside, 0.5 - 0.3 * np.sqrt(np.clip(1 - (xx / a) ** 2 - (yy / b) ** 2, 0, 1)), 0),
                      inside.astype(np.float32)))
    order = [0, 1, 0, 2, 1, 0]
    depths = np.stack([blobs[i][0] for i in order]).astype(np.float32)
    masks = np.stack([blobs[i][1] for i in order])
    first, inverse = distinct([d.tobytes() + m.tobytes() for d, m in zip(depths, masks)])
    assert first.tolist() == [0, 1, 3] and inverse.tolist() == [0, 1, 0, 2, 1, 0]
    cfg = DescriptorConfig(level=1, view_size=64, vocab=16, dense_step=6)
    # the reference: every image described on its own (separate lists, so nothing is shared or compared once)
    dirs = octahedron_views(cfg.level)
    every = distance_matrix_from_features([descriptor.view_features(v, f, cfg, dirs)
                                          for v, f in depth_meshes(depths, masks, cfg)], cfg)
    described = []
    spy = descriptor.view_features
    monkeypatch.setattr(descriptor, "view_features", lambda v, f, c, d: described.append(len(f)) or spy(v, f, c, d))
    once = distance_matrix_from_depths(depths, masks, cfg)
    assert len(described) == 3
    np.testing.assert_allclose(once, every, atol=1e-6)
    compared = []
    spy_distances = descriptor.shape_distances
    monkeypatch.setattr(descriptor, "shape_distances", lambda h, p, **kw: compared.append(len(h)) or spy_distances(h, p, **kw))
    np.testing.assert_allclose(distance_matrix_from_depths(depths, masks, cfg), every, atol=1e-6)
    assert compared == [3]  # the distances too: 3 shapes compared, not 6
    np.testing.assert_array_equal(once[0, [1, 3, 4]], once[2, [1, 3, 4]])  # copies of one image: one row


def test_mds_and_gps_baselines_are_pose_invariant():
    """A bent and a straight capsule (same intrinsic geometry) get similar canonical forms."""
    cap = trimesh.creation.capsule(height=2.0, radius=0.3, count=[12, 12])
    v = cap.vertices.copy()
    bent = v.copy()
    theta = v[:, 2] * 0.3  # bend along z into an arc (approximately isometric)
    bent[:, 0] = (1 / 0.3 + v[:, 0]) * np.cos(theta) - 1 / 0.3
    bent[:, 2] = (1 / 0.3 + v[:, 0]) * np.sin(theta)
    f = cap.faces
    D1, D2 = geodesic_matrix(v, f), geodesic_matrix(bent, f)
    assert np.abs(D1 - D2).mean() < 0.1 * D1.mean()
    e1, e2 = classical_mds(v, f, D=D1), classical_mds(bent, f, D=D2)
    s1, s2 = np.sort(np.abs(e1).max(0)), np.sort(np.abs(e2).max(0))
    assert np.allclose(s1, s2, rtol=0.15)
    g = gps_embedding(v, f)
    assert g.shape == (len(v), 3) and np.isfinite(g).all()
    sv, sf = simplify_to_vertices(v, f, 100)
    assert len(sv) <= 100 and sf.max() < len(sv)
    out = canonical_forms([(v, f)], "gps", max_vertices=200)
    assert out[0][0].shape[1] == 3
    with pytest.raises(ValueError, match="unknown canonical baseline"):
        canonical_forms([(v, f)], "nope")


def test_gps_embedding_is_deterministic():
    """Same mesh -> the same GPS embedding on every call (seeded start vector, fixed signs)."""
    import trimesh

    from lit3d.geometry.spectral import gps_embedding

    m = trimesh.creation.icosphere(subdivisions=2)
    m.vertices[:, 0] *= 1.7
    a = gps_embedding(m.vertices, m.faces)
    b = gps_embedding(m.vertices, m.faces)
    assert a.shape == (len(m.vertices), 3)
    assert np.array_equal(a, b)
