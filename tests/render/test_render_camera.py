"""The one orthographic depth camera and look_at (lit3d.render.camera)."""
from __future__ import annotations

import numpy as np
import pytest
import trimesh

from lit3d.render.camera import OrthoCamera, linear_depth_ortho, look_at, render_ortho_depth


def _check_frame(pose: np.ndarray, eye, target) -> None:
    r = pose[:3, :3]
    np.testing.assert_allclose(r.T @ r, np.eye(3), atol=1e-12)
    assert np.linalg.det(r) == pytest.approx(1.0)
    view = np.asarray(target, float) - np.asarray(eye, float)
    np.testing.assert_allclose(-r[:, 2], view / np.linalg.norm(view), atol=1e-12)  # looks down -z
    np.testing.assert_array_equal(pose[:3, 3], eye)


def test_look_at_frames_and_up_fallback():
    for eye, target in (([0, 0, 2], None), ([1.0, 2.0, -3.0], [0.5, 0.0, 0.1]), ([0, 5, 0], None)):
        _check_frame(look_at(eye, target), eye, [0, 0, 0] if target is None else target)
    np.testing.assert_array_equal(look_at([0, 0, 2]), np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 2], [0, 0, 0, 1.0]]))
    # camera y axis = up projected off the view direction
    np.testing.assert_allclose(look_at([3.0, 0, 0])[:3, 1], [0, 1, 0], atol=1e-12)
    # view parallel to up: world +z by default, the given fallback otherwise
    np.testing.assert_allclose(look_at([0, 4.0, 0])[:3, 1], [0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(look_at([0, 4.0, 0], fallback_up=[1.0, 0, 0])[:3, 1], [1, 0, 0], atol=1e-12)
    near_pole = [0.1, 4.0, 0.0]  # cos = 0.9997: between the two thresholds
    np.testing.assert_allclose(look_at(near_pole, fallback_up=[1.0, 0, 0], parallel_cos=0.99)[:3, 0] @ [1, 0, 0], 0,
                               atol=1e-12)


def test_linear_depth_inverts_pyrenders_perspective_linearisation():
    zn, zf = 0.5, 3.5
    dist = np.array([[0.0, 0.5, 1.0], [2.0, 3.0, 3.5]])
    ndc = 2 * (dist - zn) / (zf - zn) - 1  # orthographic NDC depth is linear in distance
    with np.errstate(divide="ignore"):
        raw = np.where(dist > 0, 2 * zn * zf / (zf + zn - ndc * (zf - zn)), 0.0)  # what pyrender returns
    np.testing.assert_allclose(linear_depth_ortho(raw.astype(np.float32), zn, zf), dist, rtol=1e-6)


def test_box_depth_is_the_analytic_distance_from_every_side():
    box = trimesh.creation.box(extents=[0.5, 0.4, 0.6])  # half extents 0.25, 0.2, 0.3
    cam = OrthoCamera(half_width=0.5, znear=0.5, zfar=3.5)
    poses = np.stack([look_at([0, 0, 2.0]), look_at([2.0, 0, 0]), look_at([0, -2.0, 0])])
    dist, mask = render_ortho_depth(box.vertices, box.faces, poses, 64, cam)
    assert dist.shape == mask.shape == (3, 64, 64) and dist.dtype == np.float64 and mask.dtype == bool
    for d, m, half in zip(dist, mask, (0.3, 0.25, 0.2)):
        np.testing.assert_allclose(d[m], 2.0 - half, atol=1e-5)
        assert (d[~m] == 0).all()
    # silhouette of the front view: 0.5 x 0.4 of a 1.0 x 1.0 window
    assert abs(mask[0].mean() - 0.5 * 0.4) < 0.02
    single, smask = render_ortho_depth(box.vertices, box.faces, poses[0], 64, cam)
    np.testing.assert_array_equal(single, dist[0])
    np.testing.assert_array_equal(smask, mask[0])


def test_tilted_plane_depth_is_linear_across_the_image():
    """A plane z = 0.3 x seen from +z: distance 2 - 0.3 x, linear in x (a perspective
    linearisation of the orthographic buffer would bend it)."""
    x = np.array([-0.4, 0.4, 0.4, -0.4])
    y = np.array([-0.4, -0.4, 0.4, 0.4])
    verts = np.stack([x, y, 0.3 * x], 1)
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    cam = OrthoCamera(half_width=0.5, znear=0.5, zfar=3.5)
    dist, mask = render_ortho_depth(verts, faces, look_at([0, 0, 2.0]), 50, cam)
    cx = np.broadcast_to(((np.arange(50) + 0.5) / 50 * 2 - 1) * 0.5, dist.shape)[mask]  # pixel-centre x
    slope, offset = np.polyfit(cx, dist[mask], 1)
    assert slope == pytest.approx(-0.3, abs=1e-4)
    assert offset == pytest.approx(2.0, abs=0.3 * 0.02 / 2)  # within half a pixel (0.02 wide) of the plane
    np.testing.assert_allclose(dist[mask], offset + slope * cx, atol=1e-5)


def test_depth_only_pass_culls_back_faces_even_with_cull_faces_off():
    """pyrender 0.1.45 forces back-face culling in DEPTH_ONLY passes and ignores SKIP_CULL_FACES
    (renderer.py, ``_bind_and_draw_primitive``). Pinned so that a change of this (which would
    change the retrieval descriptor's views) is noticed."""
    tri = np.array([[-0.3, -0.3, 0.0], [0.3, -0.3, 0.0], [0.0, 0.3, 0.0]])
    cam = OrthoCamera(half_width=0.5, znear=0.5, zfar=3.5)
    for cull in (True, False):
        dist, front = render_ortho_depth(tri, np.array([[0, 1, 2]]), look_at([0, 0, 2.0]), 32, cam, cull_faces=cull)
        _, back = render_ortho_depth(tri, np.array([[0, 2, 1]]), look_at([0, 0, 2.0]), 32, cam, cull_faces=cull)
        assert front.sum() > 100 and not back.any()
        np.testing.assert_allclose(dist[front], 2.0, atol=1e-5)


def test_gbuffer_depth_is_camera_distance():
    from lit3d.render.gbuffer import RenderConfig, render_gbuffer

    gb = render_gbuffer(trimesh.creation.icosphere(4), RenderConfig(size=32), "smooth")
    # unit sphere scaled to a unit box: radius 0.5, camera at distance 3 -> nearest point at 2.5
    centre = gb.depth[:, 0, 15:17, 15:17]
    assert np.allclose(centre.numpy(), 2.5, atol=0.01)
    assert (gb.depth[gb.mask] >= 2.5 - 1e-3).all() and (gb.depth[gb.mask] <= 3.0 + 1e-3).all()
