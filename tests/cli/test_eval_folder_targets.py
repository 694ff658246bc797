"""``lit3d-eval-folder PRED_DIR --targets TARGET_DIR``: real mesh and grid files paired by stem, scored
against brute-force numpy and analytic values, and its bad inputs (one line, exit 2, nothing written)."""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import trimesh

from lit3d.cli.eval_folder import main as eval_folder
from lit3d.metrics.surface import sample_mesh
from lit3d.render.convert import to_mesh

POINTS = 2000  # per surface: the brute-force distances below stay small (2000 x 2000)
SHIFT = 0.1  # the shifted box's offset along x, in the unit box's units


def _run(argv, capsys) -> tuple[int, str, str]:
    code = eval_folder([str(a) for a in argv])
    captured = capsys.readouterr()
    return code, captured.out.strip(), captured.err.strip()


@pytest.fixture
def targets(tmp_path) -> Path:
    """A unit box (.obj), a ball (.ply) and a cylinder (.off): three watertight target meshes."""
    folder = tmp_path / "targets"
    folder.mkdir()
    trimesh.creation.box((1.0, 1.0, 1.0)).export(folder / "box.obj")
    trimesh.creation.icosphere(2, 0.5).export(folder / "ball.ply")
    trimesh.creation.cylinder(0.4, 1.2, sections=24).export(folder / "can.off")
    return folder


def test_identical_predictions_score_perfectly(targets, tmp_path, capsys):
    pred = tmp_path / "pred"
    shutil.copytree(targets, pred)
    grids = tmp_path / "grids"  # a grid pair beside: a target grid and its copy as a .npz prediction
    (grids / "pred").mkdir(parents=True)
    (grids / "targets").mkdir()
    grid = np.zeros((16, 16, 16), bool)
    grid[3:12, 4:10, 5:13] = True
    np.save(grids / "targets" / "slab.npy", grid)
    np.savez_compressed(grids / "pred" / "slab.npz", occupancy=grid.astype(np.float32))
    for p, t, out in ((pred, targets, tmp_path / "out"), (grids / "pred", grids / "targets", tmp_path / "out_grids")):
        code, _, err = _run([p, "--targets", t, "--out", out, "--points", POINTS], capsys)
        assert code == 0, err
        m = json.loads((out / "metrics.json").read_text())
        assert m["pairs"] == len(list(t.iterdir())) and m["unpaired_predictions"] == []
        for row in m["items"]:
            assert row["chamfer_l1"] == 0.0 and row["chamfer_l2"] == 0.0, row
            assert row["fscore_1pct"] == row["fscore_2pct"] == row["normal_consistency"] == 1.0, row
            assert row["iou"] == 1.0 and "iou_skipped" not in row, row
        assert m["means"]["iou"]["mean"] == 1.0 and m["means"]["chamfer_l1"]["mean"] == 0.0
    assert {r["kinds"] for r in m["items"]} == {"grid/grid"}
    text = (tmp_path / "out" / "results.md").read_text()
    assert "| Chamfer-L1 (lower better) | 0 | [0, 0] | 3 |" in text
    assert "| IoU | 1.000 | [1.000, 1.000] | 3 |" in text
    # the conventions are stated on the page and in the JSON
    assert "the two directions averaged (halved)" in text and "the two directions summed" in text
    assert "f × the diagonal of the target surface's bounding box (f a share of that diagonal" in text
    assert "halved" in json.loads((tmp_path / "out" / "metrics.json").read_text())["conventions"]["chamfer_l1"]


def _brute_force(pred_file: Path, target_file: Path, fractions) -> dict:
    """Chamfer-L1/-L2, F-scores and normal consistency by exhaustive numpy distances on the samples
    the command draws (the same sampler, seed 0), the target box's diagonal known analytically."""
    p, t = (sample_mesh(to_mesh(f), POINTS, 0) for f in (pred_file, target_file))
    d = np.sqrt(((p.points[:, None, :] - t.points[None, :, :]) ** 2).sum(-1))  # (N, M)
    d_pt, d_tp = d.min(1), d.min(0)
    out = {"chamfer_l1": 0.5 * (d_pt.mean() + d_tp.mean()), "chamfer_l2": (d_pt ** 2).mean() + (d_tp ** 2).mean()}
    for f in fractions:
        tau = f * np.sqrt(3.0)  # the unit box's diagonal
        precision, recall = (d_pt <= tau).mean(), (d_tp <= tau).mean()
        out[f"fscore_{round(f * 100):d}pct"] = 2 * precision * recall / (precision + recall)
    cos_p = np.abs((p.normals * t.normals[d.argmin(1)]).sum(-1))
    cos_t = np.abs((t.normals * p.normals[d.argmin(0)]).sum(-1))
    out["normal_consistency"] = 0.5 * (cos_p.mean() + cos_t.mean())
    return out


def test_a_shifted_box_scores_its_brute_force_values(targets, tmp_path, capsys):
    pred = tmp_path / "pred"
    pred.mkdir()
    to_mesh(targets / "ball.ply").export(pred / "ball.obj")  # another format than the target's: still its pair
    shutil.copy(targets / "can.off", pred / "can.off")
    box = trimesh.creation.box((1.0, 1.0, 1.0))
    box.apply_translation((SHIFT, 0.0, 0.0))
    box.export(pred / "box.ply")
    code, _, err = _run([pred, "--targets", targets, "--out", tmp_path / "out", "--points", POINTS], capsys)
    assert code == 0, err
    m = json.loads((tmp_path / "out" / "metrics.json").read_text())
    row = next(r for r in m["items"] if r["stem"] == "box")
    assert (row["prediction"], row["target"], row["kinds"]) == ("box.ply", "box.obj", "mesh/mesh")
    expected = _brute_force(pred / "box.ply", targets / "box.obj", (0.01, 0.02))
    for key, value in expected.items():
        assert row[key] == pytest.approx(value, rel=1e-9, abs=1e-12), key
    # the shift is seen: distances of the order of the shift, not the sampling's floor
    assert 0.2 * SHIFT < row["chamfer_l1"] < SHIFT and row["fscore_1pct"] < 0.9
    # IoU of two unit boxes offset by SHIFT: (1 - SHIFT) / (1 + SHIFT), within the voxelisation's error at 64³
    assert row["iou"] == pytest.approx((1 - SHIFT) / (1 + SHIFT), abs=0.03)
    # the means: over the three pairs, with a bootstrap interval around them
    chamfers = [r["chamfer_l1"] for r in m["items"]]
    mean = m["means"]["chamfer_l1"]
    assert mean["mean"] == pytest.approx(np.mean(chamfers)) and mean["pairs"] == 3
    assert mean["low"] <= mean["mean"] <= mean["high"] and mean["low"] < mean["high"]


def test_grids_beside_meshes_in_both_frames(tmp_path, capsys):
    """A box mesh against a prediction grid of the same box: the grid's surface lies in the frame
    --mesh-frame names, so the distances stay within a voxel and the box voxelised on the grid's own
    voxels is the grid, in both frames."""
    res, lo, hi = 32, 8, 24  # voxels [8, 24) a side: about the box [-0.25, 0.25]^3 in the unit frame
    grid = np.zeros((res, res, res), bool)
    grid[lo:hi, lo:hi, lo:hi] = True
    for frame, scale, offset in (("unit", 1.0 / res, -0.5), ("voxel", 1.0, -0.5)):
        pred, tgt = tmp_path / f"pred_{frame}", tmp_path / f"tgt_{frame}"
        pred.mkdir()
        tgt.mkdir()
        np.save(pred / "cube.npy", grid)
        box = trimesh.creation.box((hi - lo - 0.5,) * 3)  # continuous voxel index [8.25, 23.75], centred at res / 2
        box.apply_translation((res / 2,) * 3)
        box.apply_scale(scale)  # continuous voxel index -> the frame's units
        box.apply_translation((offset,) * 3)
        box.export(tgt / "cube.obj")
        code, _, err = _run([pred, "--targets", tgt, "--out", tmp_path / f"out_{frame}", "--points", POINTS,
                             "--mesh-frame", frame], capsys)
        assert code == 0, (frame, err)
        row = json.loads((tmp_path / f"out_{frame}" / "metrics.json").read_text())["items"][0]
        voxel = 1.0 / res if frame == "unit" else 1.0
        # 0.25 voxel between the surfaces, plus the sampling's floor of ~.4 voxel at 2000 points
        assert row["kinds"] == "grid/mesh" and 0.1 * voxel < row["chamfer_l1"] < voxel, (frame, row)
        assert row["iou"] == 1.0, (frame, row)
    # the wrong frame is visible: the voxel-frame grid against the unit-frame box is far off
    code, _, err = _run([tmp_path / "pred_unit", "--targets", tmp_path / "tgt_unit", "--out", tmp_path / "wrong",
                         "--points", POINTS, "--mesh-frame", "voxel"], capsys)
    assert code == 0 and json.loads((tmp_path / "wrong" / "metrics.json").read_text())["items"][0]["chamfer_l1"] > 5


def test_open_meshes_get_no_iou_and_unpaired_predictions_are_named(targets, tmp_path, capsys):
    pred = tmp_path / "pred"
    shutil.copytree(targets, pred)
    open_box = trimesh.creation.box((1.0, 1.0, 1.0))
    open_box.update_faces(np.arange(len(open_box.faces)) >= 2)  # two triangles (one side) removed
    open_box.export(pred / "box.obj")
    trimesh.creation.icosphere(1, 0.3).export(pred / "extra.ply")
    to_mesh(pred / "can.off").export(pred / "other.obj")
    code, out, err = _run([pred, "--targets", targets, "--out", tmp_path / "out", "--points", POINTS], capsys)
    assert code == 0, err
    assert err.splitlines() == ["lit3d-eval-folder: note: 2 predictions without a target of their stem, "
                                "not scored: extra.ply, other.obj"]
    m = json.loads((tmp_path / "out" / "metrics.json").read_text())
    row = next(r for r in m["items"] if r["stem"] == "box")
    assert row["iou"] is None and row["iou_skipped"] == "box.obj is not watertight"
    assert m["means"]["iou"]["pairs"] == 2 and m["means"]["chamfer_l1"]["pairs"] == 3
    assert m["unpaired_predictions"] == ["extra.ply", "other.obj"]
    text = (tmp_path / "out" / "results.md").read_text()
    assert "IoU not measured for 1 pairs: box.obj is not watertight" in text and "extra.ply" in text


def test_bad_inputs_one_line_exit_2_nothing_written(targets, tmp_path, capsys):
    def case(name: str, edit) -> Path:
        pred = tmp_path / name / "pred"
        tgt = tmp_path / name / "targets"
        shutil.copytree(targets, pred)
        shutil.copytree(targets, tgt)
        return edit(pred, tgt)

    def missing(pred, tgt):
        (pred / "can.off").unlink()
        return tgt / "can.off"

    def write(path_of, data: bytes):
        def edit(pred, tgt):
            path = path_of(pred, tgt)
            path.unlink(missing_ok=True)
            path.write_bytes(data)
            return path
        return edit

    nan_obj = b"v 0 0 0\nv 1 0 0\nv nan 1 0\nf 1 2 3\n"
    cases = {
        "missing": (missing, "missing prediction of the target"),
        "unreadable_target": (write(lambda p, t: t / "ball.ply", b"ply\nformat nonsense\nend_header\n\x00\x01"),
                              "unreadable ply file"),
        "empty_target": (write(lambda p, t: t / "box.obj", b""), "empty file"),
        "no_faces": (write(lambda p, t: p / "box.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\n"), "no faces"),
        "nan_vertices": (lambda p, t: _replace(p / "can.off", p / "can.obj", nan_obj), "vertices contain NaN"),
        "empty_grid": (lambda p, t: _grid(t / "box.obj", t / "box.npy", np.zeros((8, 8, 8), bool)), "no occupied voxel"),
    }
    for name, (edit, expected) in cases.items():
        bad = case(name, edit)
        out = tmp_path / name / "out"
        code, _, err = _run([tmp_path / name / "pred", "--targets", tmp_path / name / "targets", "--out", out,
                             "--points", 200], capsys)
        assert code == 2 and len(err.splitlines()) == 1, (name, err)
        assert err.startswith("lit3d-eval-folder: error: ") and expected in err, (name, err)
        named = f"{tmp_path / name / 'pred' / 'can'}.{{obj,ply,off,npz,npy}}" if name == "missing" else str(bad)
        assert named in err and str(bad) in err, (name, err)
        assert not out.exists(), name  # nothing written, not even the folder
    # a failed run into a folder of an earlier good run leaves its files as they were
    good = tmp_path / "good"
    code, _, err = _run([targets, "--targets", targets, "--out", good, "--points", 200], capsys)
    assert code == 0, err
    before = {p.name: p.read_bytes() for p in good.iterdir()}
    code, _, err = _run([tmp_path / "no_faces" / "pred", "--targets", targets, "--out", good, "--points", 200], capsys)
    assert code == 2 and {p.name: p.read_bytes() for p in good.iterdir()} == before


def _replace(old: Path, new: Path, data: bytes) -> Path:
    old.unlink()
    new.write_bytes(data)
    return new


def _grid(old: Path, new: Path, grid: np.ndarray) -> Path:
    old.unlink()
    np.save(new, grid)
    return new


def test_the_two_forms_and_their_options(targets, tmp_path, capsys):
    out = tmp_path / "out"
    for argv, expected in (
        ([targets, targets], "no manifest.json), but shape files: to score against a folder of targets, give it "
                             f"as --targets {targets}"),
        ([targets], "give DATA_DIR (a prepared completion cache) or --targets TARGET_DIR"),
        ([targets, tmp_path, "--targets", targets], "not both"),
        ([targets, "--targets", targets, "--split", "test_same"], "--split: only with a prepared DATA_DIR"),
        ([targets, "--targets", targets, "--resolution", "4"], "--resolution 4: expected at least 8"),
        ([targets, "--targets", tmp_path / "nowhere"], f"{tmp_path / 'nowhere'}: targets folder not found"),
        ([tmp_path / "nowhere", "--targets", targets], f"{tmp_path / 'nowhere'}: predictions folder not found"),
    ):
        code, _, err = _run([*argv, "--out", out], capsys)
        assert code == 2 and len(err.splitlines()) == 1 and expected in err, (argv, err)
        assert not out.exists()
