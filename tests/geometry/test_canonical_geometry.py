"""Full-resolution canonical-form geometry: landmark MDS against full classical MDS,
ShapeDNA against the sphere's analytic spectrum and under isometric bending, and the broadside
camera convention."""

import numpy as np
import pytest
import trimesh
from scipy.spatial.distance import pdist

from lit3d.geometry.canonical_forms import canonical_forms
from lit3d.geometry.geodesics import geodesic_matrix, landmark_geodesics
from lit3d.geometry.mds import classical_mds, landmark_mds
from lit3d.geometry.spectral import shape_dna, shape_dna_distances
from lit3d.geometry.broadside import base_azimuth, broadside_azimuth
from lit3d.render.depth import render_depth, rotate_y
from tests.helpers.paths import SHARED_DATA

TOSCA = SHARED_DATA / "tosca8k"


def _capsule():
    cap = trimesh.creation.capsule(height=2.0, radius=0.3, count=[16, 16])
    return np.asarray(cap.vertices), np.asarray(cap.faces)


def test_landmark_mds_matches_full_classical_mds():
    v, f = _capsule()  # 258 vertices
    D = geodesic_matrix(v, f)
    full = pdist(classical_mds(v, f, D=D))
    # every vertex a landmark, same symmetric matrix: exactly classical MDS
    assert np.abs(pdist(landmark_mds(D, np.arange(len(v)))) - full).max() < 1e-8
    # 60 farthest-point landmarks (heat method rows): embedding distances agree within 8% on average
    idx, D_lv = landmark_geodesics(v, f, 60)
    assert D_lv.shape == (60, len(v)) and len(set(idx.tolist())) == 60
    lm = pdist(landmark_mds(D_lv, idx))
    assert np.corrcoef(full, lm)[0, 1] > 0.99  # measured .994
    assert np.abs(full - lm).mean() < 0.08 * full.mean()  # measured .048


def test_canonical_forms_stay_at_full_resolution():
    v, f = _capsule()
    for method in ("cmds", "smacof"):
        (x, ff), = canonical_forms([(v, f)], method, landmarks=40)
        assert x.shape == v.shape and ff is not None and len(ff) == len(f) and np.isfinite(x).all()


def test_shape_dna_of_a_sphere_matches_the_analytic_spectrum():
    """Sphere of radius r: eigenvalues l(l+1)/r^2 with multiplicity 2l+1 (l = 1..4: 24 values).
    Tolerance: 3% relative at 642 vertices (measured 2.6%; 0.7% at 2562 vertices)."""
    r = 2.0
    s = trimesh.creation.icosphere(subdivisions=3, radius=r)
    ref = np.concatenate([[deg * (deg + 1) / r ** 2] * (2 * deg + 1) for deg in range(1, 5)])
    vals = shape_dna(s.vertices, s.faces, k=24, normalise=False)
    assert np.abs(vals / ref - 1).max() < 0.03
    # area-normalised: scale-free (area 4 pi r^2 times l(l+1)/r^2)
    big = shape_dna(s.vertices * 3, s.faces, k=24)
    assert np.allclose(big, shape_dna(s.vertices, s.faces, k=24), rtol=1e-6)


def _strip(bend: float, stretch: float = 1.0):
    """A 2 x 0.5 triangulated strip, rolled about the y axis into an arc of curvature ``bend``
    (isometric for any ``bend``), or stretched along x by ``stretch`` (not isometric)."""
    x, y = np.meshgrid(np.linspace(-1, 1, 41) * stretch, np.linspace(-0.25, 0.25, 11))
    x, y = x.ravel(), y.ravel()
    if bend:
        v = np.stack([np.sin(bend * x) / bend, y, (1 - np.cos(bend * x)) / bend], 1)
    else:
        v = np.stack([x, y, np.zeros_like(x)], 1)
    i = np.arange(40)[None, :] + 41 * np.arange(10)[:, None]
    i = i.ravel()
    f = np.concatenate([np.stack([i, i + 1, i + 42], 1), np.stack([i, i + 42, i + 41], 1)])
    return v, f


def test_shape_dna_ignores_isometric_bending():
    flat, bent, stretched = (shape_dna(*_strip(b, s), k=12) for b, s in ((0, 1), (1.2, 1), (0, 1.3)))
    D = shape_dna_distances(np.stack([flat, bent, stretched]))
    assert np.abs(bent / flat - 1).max() < 0.02  # measured 1.5e-4 (chords of the arc: nearly exact)
    assert D[0, 1] < 0.05 * D[0, 2]  # measured 6e-4


def _quadruped():
    from datamodules.canonical.figures import figure_mesh, make_subject
    from lit3d.geometry.normalise import normalise_vertices

    v, f = figure_mesh(make_subject("quadruped", 3), None, 24)
    v, _ = normalise_vertices(rotate_y(v, 90.0))  # body along the viewing axis: seen end-on at azimuth 0
    return v, f


def test_broadside_view_shows_more_of_a_quadruped():
    v, f = _quadruped()
    a = broadside_azimuth(v, f)
    _, m_fixed = render_depth(v, f, 64, base_azimuth(v, f, "fixed"))
    _, m_broad = render_depth(v, f, 64, a)
    assert m_broad.mean() > 1.5 * m_fixed.mean()  # measured 13.1% vs 7.0% of the pixels
    # after turning, the ground-plane extent along x is the larger one
    w = rotate_y(v, a)
    assert np.ptp(w[:, 0]) > np.ptp(w[:, 2])
    with pytest.raises(ValueError):
        base_azimuth(v, f, "sideways")


@pytest.mark.skipif(not (TOSCA / "cat0.ply").is_file(), reason="../shared/data/tosca8k is absent")
def test_broadside_view_of_real_tosca_cat():
    from datamodules.canonical.tosca import read_mesh, z_up_to_y_up
    from lit3d.geometry.normalise import normalise_vertices

    v, f = read_mesh(TOSCA / "cat0.ply")
    v, _ = normalise_vertices(z_up_to_y_up(v))
    _, m0 = render_depth(v, f, 128, 0.0)
    _, m1 = render_depth(v, f, 128, broadside_azimuth(v, f))
    assert m1.mean() > 2 * m0.mean()  # measured 11.4% of the pixels vs 4.7%
