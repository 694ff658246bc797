"""``lit3d-reconstruct --body`` does not import Lightning: the body fit, its regressor and the Anny body
model (:mod:`lit3d.body_model`) sit below the DataModules, and the command loads the completion
pipeline's checkpoint code only for ``--ckpt``. Checked in a fresh interpreter, on the whole path a
``--body`` run imports before Anny loads (an image with too few foreground pixels ends it there), and
on ``anny`` itself where it is installed."""
from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from PIL import Image
from tests.helpers.paths import REPO as ROOT

LIGHTNING = ("lightning", "pytorch_lightning")

PROBE = """
import importlib.util, json, sys
from lit3d.cli.reconstruct import main
rc = main([sys.argv[1], "--body", "--out", sys.argv[2]])
if importlib.util.find_spec("anny") is not None:
    import anny  # noqa: F401  (what Body() loads at the first image that gets to the fit)
print(json.dumps({"rc": rc, "modules": sorted(sys.modules)}))
"""


def test_the_body_path_imports_no_lightning(tmp_path):
    speck = np.zeros((120, 160), np.uint16)
    speck[50:55, 70:80] = 2000  # 50 foreground pixels: refused after the body modules load, before Anny
    Image.fromarray(speck).save(tmp_path / "speck.png")
    res = subprocess.run([sys.executable, "-c", PROBE, str(tmp_path / "speck.png"), str(tmp_path / "out")],
                         cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr[-3000:]
    probe = json.loads(res.stdout.strip().splitlines()[-1])
    modules = set(probe["modules"])
    assert probe["rc"] == 2 and "speck.png: 50 foreground depth pixels" in res.stderr
    # the probe went down the body path: the fit, the regressor's loading and the body model were imported
    assert {"lit3d.reconstruct.body", "lit3d.body_fit.fit", "lit3d.body_fit.regressor", "lit3d.body_model.bodies"} <= modules
    loaded = sorted(m for m in modules if m.split(".")[0] in LIGHTNING)
    assert not loaded, f"lit3d-reconstruct --body imported Lightning: {loaded[:5]}"
    assert not any(m.split(".")[0] == "datamodules" for m in modules)


@pytest.mark.slow
def test_a_whole_body_fit_imports_no_lightning(tmp_path):
    """A person's depth image through ``lit3d-reconstruct --body`` to the end (Anny loaded, the fit, every
    output file), in a fresh interpreter."""
    import trimesh

    from lit3d.body_model.bodies import BodyModel, sample_phenotype, sample_pose
    from lit3d.reconstruct.backproject import RECGAN_FOV_DEG, Intrinsics
    from lit3d.reconstruct.synthetic import render_depth_pinhole

    model = BodyModel()
    verts = model.vertices(sample_phenotype(0, 3), [sample_pose(0, 2)])[0].astype(np.float64)
    person = trimesh.Trimesh(verts * np.array([1.0, -1.0, -1.0]) + np.array([0.05, 0.1, 2.8]), model.faces,
                             process=False)
    depth = render_depth_pinhole(person, Intrinsics.from_fov(RECGAN_FOV_DEG, 160, 120), 160, 120)
    Image.fromarray(np.round(depth * 1000).astype(np.uint16)).save(tmp_path / "person.png")
    res = subprocess.run([sys.executable, "-c", PROBE, str(tmp_path / "person.png"), str(tmp_path / "out")],
                         cwd=ROOT, capture_output=True, text=True, timeout=900)
    assert res.returncode == 0, res.stderr[-3000:]
    probe = json.loads(res.stdout.strip().splitlines()[-1])
    modules = set(probe["modules"])
    assert probe["rc"] == 0 and (tmp_path / "out" / "person_body_canonical_depth.npy").is_file()
    assert "anny" in modules and not [m for m in modules if m.split(".")[0] in LIGHTNING]
