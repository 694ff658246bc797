"""The regressor's pose mixes (lit3d.body_fit.poses): ``upright`` is the Anny data source's draw unchanged;
``varied`` draws each family at its share, keeps every joint within the fit's limits, folds hips and
knees where it says so, and turns bodies upside down and onto their side. No Anny forward pass."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from lit3d.body_model.bodies import sample_pose
from lit3d.body_fit.model import DOFS
from lit3d.body_fit.poses import FAMILIES, KNEE_BENT, POSE_MIXES, draw_pose, pose_params

LO = np.array([d.lo for d in DOFS])
HI = np.array([d.hi for d in DOFS])
UP = np.array([0.0, -1.0, 0.0])  # the body's up axis in the camera frame (y down) at rotation 0


def _up(rotvec: np.ndarray) -> np.ndarray:
    return Rotation.from_rotvec(rotvec).apply(UP)


def test_upright_mix_is_the_data_sources_draw():
    for i in range(5):
        theta, rot, family = draw_pose(3, i, "upright")
        want_theta, want_rot = pose_params(sample_pose(3, i, subject=i))
        assert family == "upright"
        np.testing.assert_array_equal(theta, want_theta)
        np.testing.assert_array_equal(rot, want_rot)
        assert np.degrees(np.linalg.norm(rot)) <= 15.0 + 1e-9
        assert _up(rot)[1] < -0.96  # within 15 degrees of upright


def test_draws_repeat_for_one_seed_and_index():
    a, b = draw_pose(5, 17, "varied"), draw_pose(5, 17, "varied")
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_array_equal(a[1], b[1])
    assert a[2] == b[2]


@pytest.fixture(scope="module")
def varied():
    return [draw_pose(9, i, "varied") for i in range(800)]


def test_varied_families_come_at_their_shares(varied):
    families = [f for _, _, f in varied]
    assert set(families) == set(FAMILIES)
    for name, share in POSE_MIXES["varied"].items():
        assert abs(families.count(name) / len(families) - share) < 0.06, name


def test_varied_joints_stay_within_the_fits_limits(varied):
    theta = np.stack([t for t, _, _ in varied])
    assert (theta >= LO - 1e-9).all() and (theta <= HI + 1e-9).all()


def test_folded_poses_flex_the_hips_and_bend_the_knees(varied):
    hips = [k for k, d in enumerate(DOFS) if d.bone.startswith("upperleg01") and d.axis[0] == 1.0]
    knees = [k for k, d in enumerate(DOFS) if d.bone.startswith("lowerleg01")]
    assert len(hips) == 2 and len(knees) == 2
    folded = np.stack([t for t, _, f in varied if f == "folded"])
    upright = np.stack([t for t, _, f in varied if f == "upright"])
    assert (folded[:, hips] <= 0).all() and (folded[:, knees] >= KNEE_BENT).all()
    assert folded[:, knees].mean() > upright[:, knees].mean() + 0.4


def test_varied_rotations_reach_lying_and_upside_down_bodies(varied):
    up_y = {f: np.array([_up(r)[1] for _, r, g in varied if g == f]) for f in FAMILIES}
    assert (up_y["upright"] < -0.96).all() and np.allclose(up_y["turned"], -1.0)
    assert (up_y["folded"] <= 1e-9).all()  # leaned by at most 90 degrees: never head down
    lying = np.abs(up_y["any"]) < 0.5  # the up axis within 30 degrees of horizontal
    inverted = up_y["any"] > 0.5
    assert 0.35 < lying.mean() < 0.65 and 0.15 < inverted.mean() < 0.35  # uniform rotations: .5 and .25
    turned_yaw = [Rotation.from_rotvec(r).as_euler("YXZ")[0] for _, r, g in varied if g == "turned"]
    assert np.ptp(turned_yaw) > 5.5  # any direction about the vertical
