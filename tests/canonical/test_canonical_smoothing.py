"""evaluation.prediction_smooth_px: the prediction's depth smoothed inside its silhouette before
it is scored, saved (heldout.npz) and pooled; the posed input and the truth are left as they are."""
from types import SimpleNamespace

import numpy as np
import pytest
import torch
from lightning.fabric.utilities.data import AttributeDict

from lit3d.canonical import evaluator, pooled
from lit3d.canonical.smoothing import SETTING, smooth_prediction
from lit3d.metrics.image.filters import masked_gaussian_blur
from tests.helpers.canonical import RETRIEVAL, pooled_datamodule, fold_outputs


def _rough(outputs):
    """The posed input as the prediction, with a +-0.05 checkerboard on its surface."""
    d = outputs["depth"].clone()
    s = d.shape[-1]
    checker = ((torch.arange(s)[:, None] + torch.arange(s)[None, :]) % 2).float() * 0.1 - 0.05
    rough = torch.where(outputs["mask"] > 0.5, d + checker, d)
    return {**outputs, "pred_depth": rough, "pred_mask": outputs["mask"] * 0.9}  # probabilities, not 0/1


@pytest.mark.parametrize("sigma", [0.0, 1.5])
def test_protocol_scores_and_saves_the_smoothed_prediction(tmp_path, sigma):
    dm = pooled_datamodule(tmp_path)
    outputs = _rough(fold_outputs(dm))
    raw = outputs["pred_depth"].clone()
    task = SimpleNamespace(hparams=AttributeDict(arch="canonical", mask_threshold=0.5), _trainer=None,
                           test_outputs=SimpleNamespace(compute=lambda: dict(outputs)))
    settings = dict(retrieval=RETRIEVAL, chance_trials=5, mesh_baselines=[], ceiling_jitter_deg=0.0,
                    retrieval_min_subjects=2, **{SETTING: sigma})
    ev = evaluator.protocol(task, dm, settings)
    held = ev.artefacts["heldout"]
    want = raw if sigma == 0 else masked_gaussian_blur(raw, (outputs["pred_mask"] >= 0.5).float(), sigma)
    np.testing.assert_allclose(held["pred_depth"].astype(np.float32), want[:, 0].numpy(), atol=1e-3)
    np.testing.assert_array_equal(held["depth"], outputs["depth"][:, 0].numpy().astype(np.float16))  # input as is
    assert '"prediction_smooth_px": %s' % sigma in str(held["settings"])
    if sigma:  # the checkerboard is gone inside the silhouette
        inside = outputs["mask"][:, 0].numpy() > 0.5
        rough_step = np.abs(np.diff(raw[:, 0].numpy(), axis=-1))[inside[..., 1:] & inside[..., :-1]].mean()
        smooth_step = np.abs(np.diff(held["pred_depth"].astype(np.float32), axis=-1))[inside[..., 1:] & inside[..., :-1]].mean()
        assert smooth_step < rough_step / 3


@pytest.mark.parametrize("sigma", [0.0, 1.5])
def test_the_posed_input_is_also_scored_on_its_outline(tmp_path, sigma):
    """With smoothing on, an ``input_outline`` row scores the posed input smoothed like the prediction: a
    prediction that is the posed input itself scores exactly that row; without smoothing there is no such row."""
    dm = pooled_datamodule(tmp_path, n_poses=6)  # 2 test poses of each of 4 subjects: retrieval is scored
    outputs = fold_outputs(dm)
    outputs = {**outputs, "pred_depth": outputs["depth"].clone(), "pred_mask": outputs["mask"].clone()}
    task = SimpleNamespace(hparams=AttributeDict(arch="canonical", mask_threshold=0.5), _trainer=None,
                           test_outputs=SimpleNamespace(compute=lambda: dict(outputs)))
    settings = dict(retrieval=RETRIEVAL, chance_trials=5, mesh_baselines=[], ceiling_jitter_deg=0.0,
                    retrieval_min_subjects=2, **{SETTING: sigma})
    metrics = evaluator.protocol(task, dm, settings).metrics
    outline = {k.rsplit("/", 1)[1]: v for k, v in metrics.items() if k.startswith("test/retrieval/input_outline/")}
    assert "test/retrieval/input/nn" in metrics and bool(outline) == bool(sigma)
    if sigma:
        assert outline == {k.rsplit("/", 1)[1]: v for k, v in metrics.items() if k.startswith("test/retrieval/model/")}


def test_pooled_smooths_unsmoothed_runs_once():
    items = {"pred_depth": np.random.default_rng(0).random((2, 16, 16)).astype(np.float16),
             "pred_mask": np.ones((2, 16, 16), np.float16)}
    settings = {"mask_threshold": 0.5}
    out = pooled.with_smoothing(items, settings, 2.0)
    assert settings[SETTING] == 2.0
    np.testing.assert_allclose(out["pred_depth"], smooth_prediction(items["pred_depth"], items["pred_mask"], 2.0),
                               atol=1e-3)
    assert out["pred_depth"].std() < items["pred_depth"].astype(np.float32).std() / 2
    with pytest.raises(ValueError, match="already smoothed"):
        pooled.with_smoothing(items, settings, 2.0)
    with pytest.raises(ValueError, match="no prediction row"):
        pooled.with_smoothing({}, {"mask_threshold": 0.5}, 2.0)
