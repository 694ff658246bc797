"""The body regressor (lit3d.body_fit.regressor, its training people datamodules.body.people, --body-init): its parts
without Anny, then a few Anny people (Anny loads once, ~15 s) for a tiny training run that must read
the height off the image better than the mean does, and for the fit from a given start."""
from __future__ import annotations

import numpy as np
import pytest
import torch
from PIL import Image

from lit3d.body_fit.errors import BodyCheckpointError
from lit3d.body_fit.fit import FitConfig, fit_body
from lit3d.body_fit.model import DOFS, PHENOTYPES
from lit3d.body_fit.depth_points import observe
from lit3d.body_fit.regressor import (BodyRegressor, Preprocess, Regressor, checkpoint, crop, fit_from_regressor,
                                  load_regressor, loss, refine_config, rotmat_6d)
from lit3d.body_fit.synthetic import Camera, sensed_depth
from lit3d.body_fit.poses import pose_params
from datamodules.body.people import Placement, draw_people, render_people, shape_distribution
from datamodules.body.replay import ReplayBuffer
from lit3d.cli.reconstruct import main
from lit3d.sensing.camera import backproject

W, H = 128, 96  # a small camera: the person is ~50 px tall at 3.2 m


def test_regressor_output_shapes_and_ranges():
    net = BodyRegressor(16, width=4, hidden=16).eval()
    out = net(torch.randn(3, 2, 16, 16), torch.randn(3, 3))
    assert out.shape == (3, len(PHENOTYPES) + len(DOFS) + 9)
    dec = net.decode(out * 10)
    assert dec["phenotype"].shape == (3, 6) and dec["theta"].shape == (3, len(DOFS))
    assert dec["rotmat"].shape == (3, 3, 3) and dec["translation"].shape == (3, 3)
    assert ((dec["phenotype"] >= 0) & (dec["phenotype"] <= 1)).all()
    lo, hi = torch.tensor([d.lo for d in DOFS]), torch.tensor([d.hi for d in DOFS])
    assert ((dec["theta"] >= lo - 1e-6) & (dec["theta"] <= hi + 1e-6)).all()
    r = rotmat_6d(torch.randn(5, 6))
    assert torch.allclose(r @ r.transpose(1, 2), torch.eye(3).expand(5, 3, 3), atol=1e-5)
    assert torch.allclose(torch.det(r), torch.ones(5), atol=1e-5)
    with pytest.raises(ValueError, match="power of two"):
        BodyRegressor(24)


def test_crop_keeps_the_foreground_centred_with_its_metric_size():
    cam = Camera.default(W, H)
    depth = np.zeros((H, W), np.float32)
    depth[10:50, 40:60] = 3.0
    depth[10:30, 40:60] = 3.2  # the upper half further away
    mask = depth > 0
    img, extras = crop(mask, backproject(depth, cam, mask), cam.fx, cam.fy, Preprocess(size=16, depth_unit=0.5))
    assert img.shape == (2, 16, 16) and extras.shape == (3,)
    assert 0 <= img[0].min() and img[0].max() <= 1 and img[0, 8, 8] == 1 and img[0, 8, 1] == 0  # box centred
    assert extras[0] == pytest.approx(40 * 3.1 / cam.fy) and extras[1] == pytest.approx(20 * 3.1 / cam.fx)
    assert extras[2] == pytest.approx(3.1)
    assert img[1, 2:6, 8].mean() > 0.1 > -0.1 > img[1, 10:14, 8].mean()  # relative depth, in half metres


def test_checkpoint_round_trip_and_bad_files(tmp_path):
    prep = Preprocess(size=16)
    net = BodyRegressor(16, width=4, hidden=16).eval()
    path = tmp_path / "reg.ckpt"
    torch.save(checkpoint(net, prep, {"width": 4, "hidden": 16}, {"steps": 1}), path)
    reg = load_regressor(path)
    x, e = torch.randn(2, 2, 16, 16), torch.randn(2, 3)
    with torch.no_grad():
        assert torch.equal(reg.net(x, e), net(x, e))
    assert reg.prep == prep and reg.path == str(path)
    bad = tmp_path / "bad.ckpt"
    bad.write_bytes(b"not a checkpoint")
    with pytest.raises(BodyCheckpointError, match=r"bad\.ckpt: not a readable checkpoint"):
        load_regressor(bad)
    other = tmp_path / "other.ckpt"
    torch.save({"state_dict": {}}, other)
    with pytest.raises(BodyCheckpointError, match=r"other\.ckpt: not a body regressor checkpoint"):
        load_regressor(other)
    torch.save(checkpoint(net, prep, {"width": 8, "hidden": 16}, {}), other)  # weights of another size
    with pytest.raises(BodyCheckpointError, match=r"other\.ckpt: body regressor checkpoint does not fit"):
        load_regressor(other)


def test_cli_body_init_with_a_corrupt_checkpoint_is_one_line(tmp_path, capsys):
    depth = np.zeros((H, W))
    depth[10:60, 40:60] = 3.0
    Image.fromarray(np.round(depth * 1000).astype(np.uint16)).save(tmp_path / "person.png")
    bad = tmp_path / "init.ckpt"
    bad.write_bytes(b"\x00garbage")
    out = tmp_path / "out"
    assert main([str(tmp_path / "person.png"), "--body", "--body-init", str(bad), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and "error:" in lines[0] and str(bad) in lines[0] and "Traceback" not in err
    assert not out.exists() or not any(out.iterdir())
    assert main([str(tmp_path / "person.png"), "--ckpt", str(bad), "--body-init", str(bad), "--out", str(out)]) == 2
    assert "--body-init CKPT: needs --body" in capsys.readouterr().err
    assert main([str(tmp_path / "person.png"), "--body", "--body-init", "none", "--body-refine-poor", "120", "--out",
                 str(out)]) == 2
    err = capsys.readouterr().err
    assert "--body-refine-poor N needs a regressor, not none" in err and len(err.strip().splitlines()) == 1
    assert not out.exists() or not any(out.iterdir())


# ------------------------------------------------------------------ Anny people (Anny loads once)
def _people(body, cam, prep, n: int, seed: int) -> dict:
    """``n`` people in the rest pose 3.2 m ahead, weight and height uniform in [0, 1], the rest 0.5."""
    g = torch.Generator().manual_seed(seed)
    pheno = torch.full((n, 6), 0.5)
    for k in ("weight", "height"):
        pheno[:, PHENOTYPES.index(k)] = torch.rand(n, generator=g)
    return render_people(body, pheno, torch.zeros(n, len(DOFS)), torch.zeros(n, 3), np.tile([0.0, 0.0, 3.2], (n, 1)),
                         cam, prep, np.random.default_rng(seed), "recgan", (W, H))


@pytest.fixture(scope="module")
def anny():
    from lit3d.body_fit.model import Body

    body = Body()
    cam, prep = Camera.default(W, H), Preprocess(size=16)
    return body, cam, prep, _people(body, cam, prep, 96, 0), _people(body, cam, prep, 24, 1)


def test_drawn_people_follow_the_pose_draw_and_the_adult_shapes(anny):
    body, cam, prep, _, _ = anny
    got = draw_people(body, shape_distribution(body), 11, 0, 3, cam, prep, Placement(image=(W, H)))
    assert got["image"].shape == (3, 2, 16, 16) and got["extras"].shape == (3, 3)
    from lit3d.body_model.bodies import sample_pose

    theta, rot = pose_params(sample_pose(11, 2, subject=2))
    assert torch.allclose(got["theta"][2], torch.tensor(theta, dtype=torch.float32))
    assert ((got["phenotype"] >= 0) & (got["phenotype"] <= 1)).all()


def test_varied_people_carry_their_drawn_rotation_as_the_target(anny):
    import roma

    from lit3d.body_fit.poses import draw_pose

    body, cam, prep, _, _ = anny
    got = draw_people(body, shape_distribution(body), 11, 0, 6, cam, prep, Placement(image=(W, H), poses="varied"))
    assert len(got["image"]) == 6  # lying or upside down, every body is still seen
    for i in range(6):
        theta, rot, _ = draw_pose(11, i, "varied")
        assert torch.allclose(got["theta"][i], torch.tensor(theta, dtype=torch.float32))
        want = roma.rotvec_to_rotmat(torch.tensor(rot, dtype=torch.float32))
        assert torch.allclose(got["rotmat"][i], want, atol=1e-5)


def _step(net, opt, batch) -> float:
    """One Adam step on ``batch`` (:func:`lit3d.body_fit.regressor.loss`); the loss before it."""
    net.train()
    total, _ = loss(net.decode(net(batch["image"], batch["extras"])), batch)
    opt.zero_grad()
    total.backward()
    opt.step()
    return float(total.detach())


def test_tiny_training_lowers_the_loss_and_beats_the_mean_height(anny):
    body, cam, prep, train, val = anny
    assert len(train["image"]) >= 90  # a body under MIN_POINTS pixels is left out
    torch.manual_seed(0)
    net = BodyRegressor(16, width=8, hidden=32)
    opt = torch.optim.Adam(net.parameters(), lr=3e-3)
    buf, gen = ReplayBuffer(128), torch.Generator().manual_seed(0)
    buf.add(train)
    history = [_step(net, opt, buf.sample(32, gen)) for _ in range(150)]
    assert np.mean(history[-20:]) < 0.2 * np.mean(history[:5])
    net.eval()
    with torch.no_grad():
        pred = net.decode(net(val["image"], val["extras"]))["phenotype"]
    i = PHENOTYPES.index("height")
    mean_err = (train["phenotype"][:, i].mean() - val["phenotype"][:, i]).abs().mean()
    assert (pred[:, i] - val["phenotype"][:, i]).abs().mean() < 0.7 * mean_err  # it reads the person, not the mean


def test_fit_from_a_given_start_runs_the_requested_steps(anny):
    from lit3d.body_model.bodies import sample_pose
    from lit3d.body_fit.model import Params

    body, cam, prep, _, _ = anny
    theta, rot = pose_params(sample_pose(11, 0, subject=0))
    start = Params(torch.full((6,), 0.4), torch.tensor(theta, dtype=torch.float32), torch.tensor(rot, dtype=torch.float32),
                   torch.tensor([0.0, 0.0, 3.2]), torch.zeros(()))
    with torch.no_grad():
        verts = body.camera_vertices(start).double().numpy()
    depth, _ = sensed_depth(verts, body.faces, cam, np.random.default_rng(0), "recgan", W, H)
    obs = observe(depth, cam, label="person")
    res = fit_body(body, obs, FitConfig(global_iters=2, full_iters=3), start)
    assert len(res.history) == 5 and res.iterations == 5
    reg = Regressor(BodyRegressor(16, width=4, hidden=8), prep)
    res = fit_from_regressor(body, reg, obs, refine_config(1, 2))
    assert len(res.history) == 3 and res.iterations == 3 and res.seconds > 0
    assert res.vertices.shape == verts.shape


def test_a_refinement_flagged_poor_goes_on_and_a_good_one_stops(anny, monkeypatch):
    import lit3d.body_fit.regressor as regressor

    body, cam, prep, _, _ = anny
    truth = body.camera_vertices(regressor.Params.mean((0.0, 0.0, 3.2))).detach().double().numpy()
    depth, _ = sensed_depth(truth, body.faces, cam, np.random.default_rng(0), "recgan", W, H)
    obs = observe(depth, cam, label="person")
    torch.manual_seed(0)
    reg = Regressor(BodyRegressor(16, width=4, hidden=8), prep)  # untrained: a start far off
    res = fit_from_regressor(body, reg, obs, refine_config(1, 2, poor_extra_iters=4))
    assert res.iterations == 7 and len(res.history) == 7  # 1 + 2 steps flagged poor, then 4 more
    assert fit_from_regressor(body, reg, obs, refine_config(1, 2)).iterations == 3  # 0: never more
    checked = []
    monkeypatch.setattr(regressor, "fit_quality", lambda *a: checked.append(1) or {"poor_fit": False})
    assert fit_from_regressor(body, reg, obs, refine_config(1, 2, poor_extra_iters=4)).iterations == 3
    assert checked == [1]
