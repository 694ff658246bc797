"""The body-fit evaluation's metrics (lit3d.body.fit_scores, lit3d.body.report) against independent references; no Anny."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.distance import cdist

from lit3d.body.fit_scores import chamfer_fscore, per_vertex_error, phenotype_error
from lit3d.body.report import spread
from lit3d.body_fit.synthetic import Camera, sensed_depth
from lit3d.reconstruct.backproject import RECGAN_FOV_DEG, Intrinsics


def test_chamfer_and_fscore_of_hand_made_point_sets():
    a = np.array([[0.0, 0, 0], [1, 0, 0], [0, 2, 0]])
    b = np.array([[0.0, 0, 0.1], [1, 0, 0.5], [5, 0, 0], [0, 2, 0]])
    # a -> b: 0.1, 0.5, 0; b -> a: 0.1, 0.5, 4, 0
    out = chamfer_fscore(a, b, (0.2, 1.0))
    assert out["pred_to_truth"] == pytest.approx(0.6 / 3)
    assert out["truth_to_pred"] == pytest.approx(4.6 / 4)
    assert out["chamfer"] == pytest.approx((0.2 + 1.15) / 2)
    p, r = 2 / 3, 2 / 4  # within 0.2
    assert out["f@0.2"] == pytest.approx(2 * p * r / (p + r))
    assert out["f@1"] == pytest.approx(2 * 1 * 0.75 / 1.75)


def test_chamfer_and_fscore_match_brute_force_on_random_sets():
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(300, 3)), rng.normal(size=(200, 3)) + 0.1
    d = cdist(a, b)
    ab, ba = d.min(1), d.min(0)
    out = chamfer_fscore(a, b, (0.3,))
    assert out["chamfer"] == pytest.approx((ab.mean() + ba.mean()) / 2)
    p, r = (ab <= 0.3).mean(), (ba <= 0.3).mean()
    assert out["f@0.3"] == pytest.approx(2 * p * r / (p + r))
    assert chamfer_fscore(a, a, (1e-9,))["f@1e-09"] == 1.0 and chamfer_fscore(a, a, (0.1,))["chamfer"] == 0.0


def test_vertex_and_phenotype_errors_and_spread():
    a = np.zeros((4, 3))
    b = np.array([[3.0, 4, 0], [0, 0, 0], [1, 0, 0], [0, 0, 2]])
    assert per_vertex_error(a, b).tolist() == [5.0, 0.0, 1.0, 2.0]
    truth = {"gender": 0.1, "age": 0.7, "muscle": 0.5, "weight": 0.5, "height": 0.9, "proportions": 0.5}
    fitted = dict(zip(truth, [0.2, 0.7, 0.5, 0.4, 0.6, 0.5]))
    err = phenotype_error(fitted, truth)
    assert err == pytest.approx({"gender": 0.1, "age": 0.0, "muscle": 0.0, "weight": 0.1, "height": 0.3,
                                 "proportions": 0.0})
    s = spread([1.0, 2.0, 3.0, 10.0])
    assert s["median"] == 2.5 and s["n"] == 4 and s["max"] == 10.0 and s["q25"] == pytest.approx(1.75)


def test_camera_is_lit3d_reconstructs_default():
    ours, theirs = Camera.default(320, 240), Intrinsics.from_fov(RECGAN_FOV_DEG, 320, 240)
    assert (ours.fx, ours.fy, ours.cx, ours.cy) == (theirs.fx, theirs.fy, theirs.cx, theirs.cy)


def test_sensed_depth_keeps_most_of_a_box_with_mm_noise():
    import trimesh

    box = trimesh.creation.box((0.5, 1.7, 0.4))
    verts = np.asarray(box.vertices) + np.array([0.0, 0.0, 3.2])
    cam = Camera.default()
    depth, info = sensed_depth(verts, np.asarray(box.faces), cam, np.random.default_rng(0))
    from lit3d.body_fit.synthetic import render

    clean = render(verts, np.asarray(box.faces), cam)
    kept = (depth > 0).sum() / (clean > 0).sum()
    assert 0.75 < kept < 0.92  # 15% holes, edges moved by the misregistration
    assert info["voxel_m"] == pytest.approx(1.7 / 256)
    both = (depth > 0) & (clean > 0)
    assert np.abs(depth[both] - clean[both]).max() < 0.02  # mm noise + a sub-cm shift


def test_pooled_reads_a_folder_of_body_fit_canonical_depths(tmp_path):
    from lit3d.canonical.pooled import folder_depths

    items = {"subject": np.array(["subject0", "subject1"]), "pose": np.array([3, 0])}
    a, b = np.zeros((8, 8), np.float32), np.ones((1, 8, 8), np.float32)
    np.save(tmp_path / "subject0_pose3_body_canonical_depth.npy", a)
    np.save(tmp_path / "subject1_pose0_body_canonical_depth.npy", b)
    d = folder_depths(items, tmp_path)
    assert d.shape == (2, 8, 8) and d[0].sum() == 0 and d[1].sum() == 64
    items["pose"] = np.array([3, 1])
    with pytest.raises(FileNotFoundError, match="1 of 2 depth images missing.*subject1_pose1"):
        folder_depths(items, tmp_path)
