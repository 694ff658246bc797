"""The shipped quality model (lit3d.quality.shipped): its file, its defaults in lit3d-score and lit3d.score."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from lit3d.quality.shipped import DEFAULT_MODEL, MODELS_DIR, ShippedModelError, load_shipped, model_names
from tests.helpers.paths import SHARED_DATA

PHIL = SHARED_DATA / "cpcd2_phil"


def test_the_shipped_model_is_package_data_with_its_card():
    assert DEFAULT_MODEL in model_names()
    model = load_shipped()
    doc = json.loads((MODELS_DIR / f"{DEFAULT_MODEL}.json").read_text())
    assert model.features and model.features[0] == doc["fusion"]["anchor"] == "pcqm"
    assert np.isfinite(model.fusion.corrections).all() and (model.fusion.corrections >= 0).all()
    assert model.fusion.opinion["kind"] == "logistic"
    assert "phil" in model.trained_on and doc["command"] and doc["cross_validated"]
    assert model.scaling.name == "MOS" and (model.scaling.lo, model.scaling.hi) == (1.0, 5.0)


def test_prediction_moves_with_its_features_and_refuses_a_table_without_them():
    model = load_shipped()
    centre = {f: 0.5 for f in model.features}
    centre["pcqm"] = 0.02  # a middling PCQM on CPCD2 phil (its values there: 0 .. 0.11)
    mid = model.predict(centre)["score"]
    assert 1.0 <= mid <= 5.0
    better = dict(centre, pcqm=0.005)  # the anchor, a distance, moved towards "better"
    assert model.predict(better)["score"] > mid
    with pytest.raises(ShippedModelError, match="coloured point-cloud"):
        model.predict({"mask_ssim/jade/flat": 0.9})


def test_a_broken_model_file_is_one_clear_error(tmp_path, monkeypatch):
    import lit3d.quality.shipped as shipped

    (tmp_path / "bad.json").write_text('{"name": "bad", "fusion": {"features": ["a"], "coef": [1, 2]}}')
    monkeypatch.setattr(shipped, "MODELS_DIR", tmp_path)
    with pytest.raises(ShippedModelError, match="bad.json: not a readable shipped quality model"):
        shipped.load_shipped("bad")
    with pytest.raises(ShippedModelError, match="no shipped quality model 'nope'"):
        shipped.load_shipped("nope")


@pytest.mark.skipif(not (PHIL / "mos.csv").is_file(), reason="../shared/data/cpcd2_phil not here")
def test_lit3d_score_prints_the_shipped_models_opinion_score_on_two_cpcd2_files(tmp_path):
    ref, dist = PHIL / "Original" / "phil.zip", PHIL / "Database_10" / "phil_N_35.zip"
    env = {"LIT3D_CACHE": str(tmp_path), "PATH": str(Path(sys.executable).parent)}
    out = subprocess.run([sys.executable, "-m", "lit3d.cli.score", str(ref), str(dist)], capture_output=True,
                         text=True, env=env, timeout=600)
    assert out.returncode == 0, out.stderr
    last = out.stdout.strip().splitlines()
    line = next(ln for ln in last if ln.startswith("predicted quality (model shipped"))
    score = float(line.rsplit(":", 1)[1])
    assert 1.0 <= score <= 5.0 and "trained on CPCD2.0 phil" in out.stdout
    raw = subprocess.run([sys.executable, "-m", "lit3d.cli.score", str(ref), str(dist), "--unlearned"],
                         capture_output=True, text=True, env=env, timeout=600)
    assert raw.returncode == 0 and "predicted quality" not in raw.stdout
    assert raw.stdout.strip().splitlines()[-1].startswith("overall score (mean Mask-SSIM)")
