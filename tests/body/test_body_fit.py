"""The Anny body fit (lit3d.body_fit, lit3d-reconstruct --body): fast checks of its parts and of bad
input without Anny; the fits themselves (Anny loads in ~30 s) are ``slow``."""
from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from omegaconf import OmegaConf
from PIL import Image

from datamodules.canonical.rendering import PairRenderer
from datamodules.canonical.settings import RenderSettings, parse
from lit3d.body_fit.errors import BodyFitError
from lit3d.body_fit.model import DOFS
from lit3d.body_fit.depth_points import backproject, observe
from lit3d.body_fit.results import canonical_depth
from lit3d.body_fit.surface import silhouette_excess
from lit3d.body_model import bodies
from lit3d.cli.reconstruct import main
from lit3d.reconstruct import backproject as recon_bp
from tests.helpers.body import INTR, H, W, save_depth_mm

# ------------------------------------------------------------------ parts (no Anny)
def test_backprojection_is_the_reconstruct_one_and_too_few_points_are_refused():
    rng = np.random.default_rng(0)
    depth = np.where(rng.random((H, W)) > 0.5, rng.uniform(1, 3, (H, W)), 0.0)
    mask = depth > 0
    assert np.allclose(backproject(depth, INTR, mask), recon_bp.backproject(depth, INTR, mask))
    sparse = np.zeros((H, W))
    sparse[50:55, 70:80] = 2.0  # 50 pixels
    with pytest.raises(BodyFitError, match=r"scan\.png: 50 foreground depth pixels"):
        observe(sparse, INTR, label="scan.png")


def test_silhouette_term_is_zero_inside_and_metres_outside():
    depth = np.zeros((H, W))
    depth[30:90, 60:100] = 2.0
    obs = observe(depth, INTR)
    outside = torch.from_numpy(obs.outside_px)[None, None]
    z = 2.0
    inside = torch.tensor([[(80 - INTR.cx) * z / INTR.fx, (60 - INTR.cy) * z / INTR.fy, z]])
    far = torch.tensor([[(120 - INTR.cx) * z / INTR.fx, (60 - INTR.cy) * z / INTR.fy, z]])  # 21 px right of the mask
    assert float(silhouette_excess(inside, obs, outside)[0]) == 0.0
    assert float(silhouette_excess(far, obs, outside)[0]) == pytest.approx(21 * z / INTR.fx, rel=0.05)


def test_fit_dofs_span_the_data_sources_poses_within_its_limits():
    assert len(DOFS) == 25
    bones = {d.bone for d in DOFS}
    for i in range(20):
        pose = bodies.sample_pose(0, i)
        assert set(pose) - {"root"} == bones
        for bone, rotvec in pose.items():
            if bone == "root":
                continue
            dofs = [d for d in DOFS if d.bone == bone]
            axes = np.array([d.axis for d in dofs])
            angles = np.linalg.lstsq(axes.T, rotvec, rcond=None)[0]
            assert np.allclose(axes.T @ angles, rotvec, atol=1e-9), bone  # representable
            for d, a in zip(dofs, angles):
                assert d.lo - 1e-9 <= a <= d.hi + 1e-9, (bone, a, d)


def test_canonical_depth_is_rendered_as_the_canonical_task_renders_anny_targets():
    import trimesh

    mesh = trimesh.creation.capsule(height=1.2, radius=0.25)
    v = np.asarray(mesh.vertices) * np.array([1.0, 1.0, 0.6])
    f = np.asarray(mesh.faces)
    hp = OmegaConf.load("conf/data/anny.yaml")

    class Stub:
        def mesh(self, subject, pose):
            return v, f

        def canonical_pose(self, subject):
            return "canonical"

    ours = canonical_depth(v + 5.0, f, int(hp.image_size))  # the offset is normalised away
    render = parse(RenderSettings, OmegaConf.to_container(hp.render), "render")
    theirs = PairRenderer(Stub(), render, int(hp.image_size)).render_views("s", v, f)[0][0]
    assert ours.shape == (hp.image_size, hp.image_size) and (ours > 0).mean() > 0.05
    assert np.array_equal(ours, theirs)


def test_cli_body_bad_input_gives_one_line_before_anny_loads(tmp_path, capsys):
    save_depth_mm(tmp_path / "empty.png", np.zeros((H, W)))
    sparse = np.zeros((H, W))
    sparse[50:55, 70:80] = 2.0
    save_depth_mm(tmp_path / "speck.png", sparse)
    out = tmp_path / "out"
    assert main([str(tmp_path / "empty.png"), str(tmp_path / "speck.png"), "--body", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if "error:" in ln]
    assert len(lines) == 2 and "Traceback" not in err
    assert "empty.png: all background" in lines[0] and "speck.png: 50 foreground depth pixels" in lines[1]
    assert not out.exists() or not any(out.iterdir())
    assert main([str(tmp_path / "empty.png"), "--body", "--ckpt", "c.ckpt", "--out", str(out)]) == 2
    assert "--body (Anny fit) goes without --ckpt" in capsys.readouterr().err


# ------------------------------------------------------------------ fits (Anny)
@pytest.fixture(scope="module")
def body():
    from lit3d.body_fit.model import Body

    return Body()


def _person(body, subject=3, pose=2):
    """Camera-frame vertices ``(V, 3)`` of a known Anny person 2.8 m in front of the camera, and its depth."""
    import trimesh

    from lit3d.reconstruct.synthetic import render_depth_pinhole

    vy = body.model.vertices(bodies.sample_phenotype(0, subject), [bodies.sample_pose(0, pose)])[0]
    truth = vy.astype(np.float64) * np.array([1.0, -1.0, -1.0]) + np.array([0.05, 0.1, 2.8])
    return truth, render_depth_pinhole(trimesh.Trimesh(truth, body.faces, process=False), INTR, W, H)


def test_evaluation_people_of_either_pose_mix_agree_on_the_upright_draw(body, monkeypatch):
    """``anny_person``'s two paths (the data source's body model; theta and rotation through
    ``Body.place``) give one body for an upright pose: the pose conventions of lit3d.body_fit.poses hold."""
    from lit3d.body.fit_scores import anny_person

    pheno = bodies.sample_phenotype(1000, 4, "adult", body.model.model)
    upright, rest = anny_person(body, pheno, 1000, 4, "upright")
    import lit3d.body_fit.poses as poses

    monkeypatch.setitem(poses.POSE_MIXES, "upright_only", {"upright": 1.0})
    placed, rest2 = anny_person(body, pheno, 1000, 4, "upright_only")  # the same draw, through Body.place
    shift = (upright - placed).mean(0)
    assert np.abs(upright - placed - shift).max() < 2e-3  # one body, up to where its centre is put
    np.testing.assert_allclose(rest, rest2, atol=1e-5)


@pytest.mark.slow
def test_fit_recovers_a_known_person_far_better_than_the_mean_body(body):
    from lit3d.body_fit.fit import FitConfig, fit_body
    from lit3d.body_fit.results import fit_outputs

    truth, depth = _person(body)
    obs = observe(depth, INTR, label="person")
    mean = fit_body(body, obs, FitConfig(full_iters=0))  # the mean body, placed and scaled only
    fit = fit_body(body, obs)
    err_mean = np.median(np.linalg.norm(mean.vertices - truth, axis=1))
    err_fit = np.median(np.linalg.norm(fit.vertices - truth, axis=1))
    print(f"median per-vertex error: fit {1000 * err_fit:.0f} mm, mean body {1000 * err_mean:.0f} mm; "
          f"fit {fit.seconds:.1f} s wall")
    assert err_fit < 0.3 * err_mean and err_fit < 0.06
    out = fit_outputs(body, fit, obs)
    assert not out.quality["poor_fit"], out.quality
    assert out.posed.shape == out.canonical.shape and out.canonical_depth.shape == (128, 128)


@pytest.mark.slow
def test_cli_body_writes_every_file_and_flags_a_box(body, tmp_path, capsys, monkeypatch):
    import trimesh

    import lit3d.reconstruct.body as rb
    from lit3d.reconstruct.synthetic import render_depth_pinhole

    monkeypatch.setattr(rb, "Body", lambda: body)  # the module's loaded Anny, not a second one
    _, depth = _person(body)
    save_depth_mm(tmp_path / "person.png", depth)
    box = trimesh.creation.box((0.6, 1.0, 0.5))
    box.apply_translation((0.0, 0.2, 2.8))
    save_depth_mm(tmp_path / "box.png", render_depth_pinhole(box, INTR, W, H))
    out = tmp_path / "out"
    assert main([str(tmp_path / "person.png"), str(tmp_path / "box.png"), "--body", "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert "Traceback" not in err
    assert [ln for ln in err.splitlines() if "POOR FIT" in ln and "box.png" in ln]
    for stem in ("person", "box"):
        assert sorted(p.name for p in out.glob(f"{stem}_*")) == sorted(rb.body_files(stem, "obj"))
    person = json.loads((out / "person_body.json").read_text())
    assert person["poor_fit"] is False and set(person["params"]["phenotype"]) == set(bodies.PHENOTYPE_RANGES)
    assert json.loads((out / "box_body.json").read_text())["poor_fit"] is True
    posed = trimesh.load(out / "person_body.obj", process=False)
    canon = trimesh.load(out / "person_body_canonical.obj", process=False)
    assert len(posed.vertices) == len(canon.vertices) and np.array_equal(posed.faces, canon.faces)
    assert np.load(out / "person_body_canonical_depth.npy").shape == (128, 128)
    assert Image.open(out / "person_body.png").height >= 256
    assert main([str(tmp_path / "person.png"), "--body", "--out", str(out)]) == 0  # a rerun skips the set
    assert "already reconstructed" in capsys.readouterr().err
