"""The model zoo (lit3d.zoo): its registry, lit3d.models() / lit3d.load(name), the CLIs' defaults, and the
shipped body regressor on held-out Anny people (a broken or untrained net fails it)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

import lit3d
from lit3d.zoo import ZOO, ZooError, zoo_model
from tests.helpers.paths import REPO as ROOT



def test_every_zoo_model_is_installed_small_and_has_a_card():
    listed = {m["name"]: m for m in lit3d.models()}
    assert set(listed) == set(ZOO) >= {"completion-furniture", "canonical-people", "body-regressor", "cpcd2-phil-fusion"}
    assert all(m["bytes"] for m in listed.values()), "a zoo file is missing from the package"
    assert sum(m["bytes"] for m in listed.values()) < 50e6
    for m in listed.values():
        assert (ROOT / m["card"]).is_file(), m["card"]
        assert m["command"] and m["trained_on"]
    with pytest.raises(ZooError, match="zoo has: completion-furniture, canonical-people, body-regressor"):
        zoo_model("canonical-animals")


def test_load_takes_a_zoo_name():
    from lit3d.body_fit.regressor import Regressor
    from lit3d.quality.shipped import ShippedQualityModel

    assert isinstance(lit3d.load("body-regressor"), Regressor)
    assert isinstance(lit3d.load("cpcd2-phil-fusion"), ShippedQualityModel)


def test_body_start_defaults_to_the_zoo_regressor_and_none_means_the_mean_body(tmp_path):
    from lit3d.cli.reconstruct import main
    from lit3d.reconstruct.body import start_label, start_regressor

    shipped = start_regressor(None)
    assert Path(shipped.path).resolve() == zoo_model("body-regressor").path
    assert "shipped body-regressor" in start_label(shipped)
    assert start_regressor("none") is None and start_label(None).startswith("mean body")
    img = tmp_path / "d.npy"
    np.save(img, np.ones((8, 8), np.float32))
    assert main([str(img), "--body", "--body-init", "none", "--body-refine-poor", "5", "--out", str(tmp_path / "o")]) == 2


def test_the_shipped_body_regressor_reads_held_out_people():
    from lit3d.body_fit.model import Body
    from lit3d.body_fit.regressor import BodyRegressor, loss
    from lit3d.body_fit.synthetic import HEIGHT, WIDTH, Camera
    from datamodules.body.people import Placement, draw_people, shape_distribution

    shipped = lit3d.load("body-regressor")
    body = Body()
    # the evaluation's held-out seed, never trained on; the pose mix it was trained on
    people = draw_people(body, shape_distribution(body), 1000, 0, 16, Camera.default(WIDTH, HEIGHT), shipped.prep,
                         Placement(poses="upright"))
    torch.manual_seed(0)
    untrained = BodyRegressor(shipped.prep.size, **{k: v for k, v in _net_args(shipped).items()}).eval()
    with torch.no_grad():
        ours, terms = loss(shipped.net.decode(shipped.net(people["image"], people["extras"])), people)
        blank, _ = loss(untrained.decode(untrained(people["image"], people["extras"])), people)
        pred = shipped.net.decode(shipped.net(people["image"], people["extras"]))
    assert float(ours) < 0.3 * float(blank)
    assert (pred["phenotype"] - people["phenotype"]).abs().mean() < 0.25
    assert (pred["translation"] - people["translation"]).norm(dim=1).median() < 0.1  # metres


def _net_args(regressor) -> dict:
    ck = torch.load(regressor.path, weights_only=True)  # a slim lit3d-train experiment=body_regressor checkpoint
    return dict(ck["hyper_parameters"]["net"])


# the card's fixed evaluation (docs/models/completion_furniture.md): four built-in procedural pieces of
# furniture, never trained on (their own seeds), rendered and completed by lit3d-reconstruct's pipeline
FURNITURE_VIEWS = (("chair", 100, 40.0), ("chair", 101, -60.0), ("table", 102, 30.0), ("couch", 103, 120.0))
FURNITURE_IOU = 0.5564           # mean IoU of the completed grids, recorded from the shipped file
FURNITURE_VISIBLE_IOU = 0.2573   # the visible surface voxels alone


def test_the_shipped_completion_model_reproduces_its_card():
    """Fails when the weights, the preprocessing (camera, placement, grid geometry) or the threshold drift."""
    from datamodules.completion.furniture import make_shape, shape_mesh
    from lit3d.reconstruct.pipeline import Completer
    from studies.reconstruct.check import round_trip

    completer = lit3d.load("completion-furniture")
    assert isinstance(completer, Completer) and completer.geometry.target_res == 64
    rows = [round_trip(shape_mesh(make_shape(cat, np.random.default_rng(seed))), completer, azimuth=az,
                       elevation=25.0, label=cat) for cat, seed, az in FURNITURE_VIEWS]
    completed = float(np.mean([r["iou_completed"] for r in rows]))
    visible = float(np.mean([r["iou_partial"] for r in rows]))
    # tolerance: CPU kernels and BLAS builds move single voxels at the threshold; 0.005 IoU is about 1%
    assert completed == pytest.approx(FURNITURE_IOU, abs=0.005)
    assert visible == pytest.approx(FURNITURE_VISIBLE_IOU, abs=0.005)
    assert completed > visible + 0.2


# the card's fixed check (docs/models/canonical_people.md): six held-out Anny people (body and own-pose seed 1000,
# never trained on), each in one pose, rendered as the canonical task renders them
PEOPLE_MASK_IOU = 0.9144         # mean mask IoU of the canonical form against the rest pose, from the shipped file
PEOPLE_INPUT_MASK_IOU = 0.3924   # the posed input's own mask against the rest pose


def test_the_shipped_canonical_model_reproduces_its_card():
    """Fails when the weights, the rendering of the input or the mask threshold drift."""
    from lit3d.body_fit.results import canonical_depth
    from lit3d.body_model.bodies import BodyModel, sample_phenotype, sample_pose
    from lit3d.reconstruct.canonical import CanonicalMapper

    model = lit3d.load("canonical-people")
    assert isinstance(model, CanonicalMapper)
    body = BodyModel()
    ours, posed = [], []
    for k in range(6):
        rest, pose = body.vertices(sample_phenotype(1000, k, "adult", body.model), [None, sample_pose(1000, 0, subject=k)])
        truth = canonical_depth(rest, body.faces, model.image_size) > 0
        depth = canonical_depth(pose, body.faces, model.image_size)
        form = lit3d.canonical_form(depth, model)
        ours.append(_iou(form.mask, truth))
        posed.append(_iou(depth > 0, truth))
    # tolerance: CPU kernels move single pixels at the mask threshold; .005 is under 1% of the figure
    assert np.mean(ours) == pytest.approx(PEOPLE_MASK_IOU, abs=0.005)
    assert np.mean(posed) == pytest.approx(PEOPLE_INPUT_MASK_IOU, abs=0.005)
    assert np.mean(ours) > np.mean(posed) + 0.3


def _iou(a: np.ndarray, b: np.ndarray) -> float:
    a, b = np.asarray(a, bool), np.asarray(b, bool)
    return float((a & b).sum() / max((a | b).sum(), 1))
