"""studies/body/faust_chain.py (the completion chain row): a person-sized mesh goes through lit3d.complete and is
scored with the body fit's measures; the table has one row with the median and quartiles."""
from pathlib import Path

import numpy as np
import trimesh

import lit3d
from lit3d.body_fit.synthetic import Camera
from studies.body import body_fit_rows as rows
from studies.body import faust_chain as chain
from lit3d.body.fit_scores import DISTANCE, FAUST_HEIGHT, camera_frame


def test_a_standing_box_is_completed_and_scored(tmp_path, one_torch_thread):
    completer = lit3d.load(lit3d.untrained_checkpoint("completion_demo", tmp_path / "c.ckpt"))
    box = trimesh.creation.box((0.4, FAUST_HEIGHT, 0.3))
    verts = np.asarray(box.vertices) + np.array([0.0, 0.0, DISTANCE])  # camera frame: centred, 3.2 m ahead
    row = chain.score_mesh("box", verts, np.asarray(box.faces), completer, Camera.default(), samples=2000)
    assert row["faces"] > 0 and np.isfinite(row["chamfer"]) and row["chamfer"] > 0
    assert 0.0 <= row["f@0.017"] <= row["f@0.034"] <= 1.0  # a larger threshold never scores less
    table = chain.markdown([row, {**row, "chamfer": 3 * row["chamfer"]}], tmp_path / "c.ckpt")
    assert "| completion chain | " in table and f"{2 * row['chamfer']:.0f} [" in table  # median of the two


def test_body_fit_rows_place_a_y_up_mesh_in_front_of_the_camera():
    """lit3d.body.fit_scores.camera_frame (FAUST and studies/body/body_fit_rows.py): a y-up mesh facing +z becomes
    camera-frame (y down, z forward), centred on its box, its centre 3.2 m ahead, scaled; the script's
    regressor fits go beside its mean-body fits."""
    v = np.array([[0.0, 0.0, 0.0], [0.0, 2.0, 0.0], [1.0, 1.0, 0.5]])  # head up at y = 2, nose towards +z
    cam = camera_frame(v, 0.5)
    assert np.allclose((cam.min(0) + cam.max(0)) / 2, [0.0, 0.0, DISTANCE])
    assert cam[1, 1] < cam[0, 1]  # the head is up: smaller y in the camera frame (y down)
    assert cam[2, 2] < DISTANCE    # the front faces the camera: nearer
    assert np.isclose(np.ptp(cam[:, 1]), 1.0)  # scaled by 0.5
    assert rows.refined_dir(Path("/x/fit")) == Path("/x/fit_refined")
