"""Surface metrics of completion (lit3d.metrics.surface): against brute-force numpy, analytic
shapes, a DDP-style merge of states, the results.md tables, and lit3d-eval-folder on real files."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
import trimesh

from lit3d.cli.eval_folder import main as eval_folder
from lit3d.completion.report import write_results
from lit3d.metrics.surface import (EMPTY_CHAMFER, SurfaceMetrics, fscore_key, grid_surface, sample_grids,
                                   surface_scores)

FRACTIONS = (0.01, 0.02, 0.05)


def ball(res: int, radius: float, centre=None) -> np.ndarray:
    """``(res, res, res)`` bool solid ball (voxel centres within ``radius`` voxels of ``centre``)."""
    c = np.full(3, (res - 1) / 2) if centre is None else np.asarray(centre, float)
    idx = np.stack(np.meshgrid(*[np.arange(res)] * 3, indexing="ij"), -1)
    return ((idx - c) ** 2).sum(-1) <= radius**2


def blobs(n: int, res: int = 12, seed: int = 0) -> np.ndarray:
    """``(n, res, res, res)`` bool random boxy shapes (unions of 3 boxes)."""
    g = np.random.default_rng(seed)
    out = np.zeros((n, res, res, res), bool)
    for s in range(n):
        for _ in range(3):
            lo = g.integers(1, res // 2, 3)
            hi = lo + g.integers(2, res // 2, 3)
            out[s, lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]] = True
    return out


def brute_force(p, t, fractions):
    """Chamfer-L1, F-scores and normal consistency from the full pairwise distance matrix."""
    d = np.sqrt(((p.points[:, None, :] - t.points[None, :, :]) ** 2).sum(-1))  # (n, m)
    d_pt, d_tp = d.min(1), d.min(0)
    tau = np.asarray(fractions) * t.diagonal
    prec = np.array([(d_pt <= x).mean() for x in tau])
    rec = np.array([(d_tp <= x).mean() for x in tau])
    f = np.where(prec + rec > 0, 2 * prec * rec / np.maximum(prec + rec, 1e-300), 0)
    nc = 0.5 * (np.abs((p.normals * t.normals[d.argmin(1)]).sum(1)).mean()
                + np.abs((t.normals * p.normals[d.argmin(0)]).sum(1)).mean())
    return 0.5 * (d_pt.mean() + d_tp.mean()), f, nc


def test_scores_match_brute_force_on_small_shapes():
    preds, targets = blobs(4, seed=1), blobs(4, seed=2)
    ps, ts = sample_grids(preds, 400, 0), sample_grids(targets, 400, 0)
    metric = SurfaceMetrics(["a", "b"], points=400, fscore_at=FRACTIONS)
    metric.update(torch.from_numpy(preds)[:, None], torch.from_numpy(targets)[:, None], torch.tensor([0, 1, 0, 1]))
    expected = []
    for p, t in zip(ps, ts):
        got = surface_scores(p, t, FRACTIONS)
        chamfer, f, nc = brute_force(p, t, FRACTIONS)
        assert got["chamfer_l1"] == pytest.approx(chamfer, rel=1e-12)
        np.testing.assert_allclose(got["fscore"], f, rtol=1e-12)
        assert got["normal_consistency"] == pytest.approx(nc, rel=1e-9)
        expected.append((chamfer, f, nc))
    assert 0 < np.mean([e[1][1] for e in expected]) < 1  # the shapes differ: neither 0 nor 1
    res = metric.compute()
    assert float(res["chamfer_l1"]) == pytest.approx(np.mean([e[0] for e in expected]), rel=1e-12)
    np.testing.assert_allclose(res["fscore"].numpy(), np.mean([e[1] for e in expected], 0), rtol=1e-12)
    assert float(res["chamfer_l1_per_category"][1]) == pytest.approx((expected[1][0] + expected[3][0]) / 2)
    assert res["count_per_category"].tolist() == [2.0, 2.0]


def test_grid_surface_is_in_the_unit_frame():
    grid = np.zeros((8, 8, 8), bool)
    grid[2, 5, 7] = True  # one voxel: its surface lies within half a voxel of its centre
    verts, faces = grid_surface(grid)
    centre = (np.array([2, 5, 7]) + 0.5) / 8 - 0.5
    assert len(faces) and np.abs(verts - centre).max() <= 0.5 / 8 + 1e-12
    full = grid_surface(np.ones((8, 8, 8)))[0]  # every voxel: the surface is the grid's cube [-0.5, 0.5]^3
    np.testing.assert_allclose([full.min(), full.max()], [-0.5, 0.5])


def test_spheres_analytic():
    res, r, d = 64, 20.0, 2.0
    small, large = ball(res, r)[None, None], ball(res, r + d)[None, None]
    one = torch.tensor([0])
    metric = SurfaceMetrics(["s"], points=6000, fscore_at=[0.01, 0.05])
    metric.update(torch.from_numpy(small), torch.from_numpy(large), one)
    got = metric.compute()
    assert float(got["chamfer_l1"]) == pytest.approx(d / res, rel=0.1)  # surfaces d voxels apart
    tau = lambda f: f * 2 * (r + d) / res * np.sqrt(3)  # noqa: E731 (F-score thresholds: f x target diagonal)
    assert tau(0.01) < d / res < tau(0.05)
    assert float(got["fscore"][0]) < 0.1 and float(got["fscore"][1]) > 0.99
    metric.reset()
    metric.update(torch.from_numpy(large), torch.from_numpy(large), one)  # identical shapes
    same = metric.compute()
    assert float(same["chamfer_l1"]) == 0.0 and same["fscore"].tolist() == [1.0, 1.0]
    assert float(same["normal_consistency"]) == pytest.approx(1.0, abs=1e-12)
    # the sampling floor: the same sphere sampled with another seed. For n uniform points on area A the
    # mean nearest-neighbour distance is 0.5 sqrt(A / n) (2-D Poisson process)
    verts, faces = grid_surface(large[0, 0])
    tri = verts[faces]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1).sum()
    other = surface_scores(sample_grids(large, 6000, 1)[0], sample_grids(large, 6000, 0)[0], [0.01, 0.02])
    assert other["chamfer_l1"] == pytest.approx(0.5 * np.sqrt(area / 6000), rel=0.05)
    assert other["fscore"][1] > 0.99


def test_empty_prediction_and_empty_target():
    target = torch.from_numpy(ball(16, 5))[None, None]
    metric = SurfaceMetrics(["s"], points=500, fscore_at=[0.01])
    metric.update(torch.zeros_like(target), target, torch.tensor([0]))
    metric.update(target, torch.zeros_like(target), torch.tensor([0]))  # no target surface: left out
    got = metric.compute()
    # (torchmetrics squeezes one-element results to 0-d tensors)
    assert float(got["chamfer_l1"]) == EMPTY_CHAMFER and float(got["fscore"]) == 0.0
    assert float(got["normal_consistency"]) == 0.0
    assert float(got["count_per_category"]) == 1.0 and float(got["empty_per_category"]) == 1.0


def test_merged_states_equal_one_process():
    preds, targets = blobs(6, seed=3), blobs(6, seed=4)
    preds[5] = False  # an empty prediction on the second "process"
    cats = torch.tensor([0, 1, 1, 0, 1, 0])
    p, t = torch.from_numpy(preds)[:, None], torch.from_numpy(targets)[:, None]
    one = SurfaceMetrics(["a", "b"], points=300, fscore_at=FRACTIONS)
    one.update(p, t, cats)
    rank0, rank1 = (SurfaceMetrics(["a", "b"], points=300, fscore_at=FRACTIONS) for _ in range(2))
    rank0.update(p[:2], t[:2], cats[:2])
    rank1.update(p[2:4], t[2:4], cats[2:4])
    rank1.update(p[4:], t[4:], cats[4:])
    rank0.merge_state(rank1)  # the states' dist_reduce_fx ("sum"), as the DDP sync applies them
    want, got = one.compute(), rank0.compute()
    for k in want:
        torch.testing.assert_close(got[k], want[k], rtol=1e-12, atol=1e-15, equal_nan=True)
    assert float(got["empty_per_category"].sum()) == 1.0


def test_completion_wiring_thresholds_each_source_and_shares_repeated_grids():
    from lit3d.completion.surface_eval import CACHE_SIZE, SurfaceTestMetrics

    targets = torch.from_numpy(blobs(5, seed=5)).float()[:, None]
    model = torch.rand(5, 1, 12, 12, 12, generator=torch.Generator().manual_seed(0))
    prior = torch.rand(1, 1, 12, 12, 12, generator=torch.Generator().manual_seed(1)).expand(5, -1, -1, -1, -1)
    cats = torch.tensor([0, 1, 0, 1, 0])
    wired = SurfaceTestMetrics(("same",), ("model", "prior"), ["a", "b"], points=300, fscore_at=[0.01, 0.02])
    wired.update("same", {"model": model, "prior": prior}, targets, cats, {"model": 0.6, "prior": 0.4})
    assert len(wired._cache) <= CACHE_SIZE
    got = wired.values()
    for src, probs, t in (("model", model, 0.6), ("prior", prior, 0.4)):
        direct = SurfaceMetrics(["a", "b"], points=300, fscore_at=[0.01, 0.02])
        direct.update(probs >= t, targets, cats)
        want = direct.compute()
        suffix = "" if src == "model" else "_prior"
        assert got[f"test/same/chamfer_l1{suffix}"] == pytest.approx(float(want["chamfer_l1"]), rel=1e-12)
        assert got[f"test/same/fscore_2pct{suffix}/b"] == pytest.approx(float(want["fscore_per_category"][1, 1]))
    assert not any("unseen" in k for k in got)


def test_results_md_has_surface_rows_for_the_model_and_every_baseline(tmp_path):
    metrics = {"test/same/iou": 0.5}
    for i, suffix in enumerate(("", "_input", "_extrusion", "_prior")):
        metrics.update({f"test/same/chamfer_l1{suffix}": 0.01 * (i + 1), f"test/same/normal_consistency{suffix}": 0.8,
                        f"test/same/{fscore_key(0.01)}{suffix}": 0.4 - 0.1 * i,
                        f"test/same/{fscore_key(0.02)}{suffix}": 0.6, f"test/same/surface_empty{suffix}": 0.0})
    text = write_results(metrics, tmp_path).read_text()
    table = text.split("## Surface metrics, same view")[1].split("\n\n")[1]
    assert "| method | IoU | Chamfer-L1 (lower better) | F-score@1% | F-score@2% | normal consistency | empty |" in table
    for label, chamfer, f1 in (("lit3d, multi-category (ours)", "0.0100", "0.400"),
                               ("input as prediction (ours)", "0.0200", "0.300"),
                               ("silhouette extrusion (ours)", "0.0300", "0.200"),
                               ("per-voxel prior (ours)", "0.0400", "0.100")):
        row = next(ln for ln in table.splitlines() if ln.startswith(f"| {label} |"))
        assert row.split(" | ")[2:4] == [chamfer, f1], row


# ------------------------------------------------------------------ lit3d-eval-folder
@pytest.fixture(scope="module")
def prepared(tmp_path_factory):
    """A tiny prepared completion split: 4 same-view test items at 32^3."""
    from datamodules.completion import CompletionDataModule
    from datamodules.completion.voxel_cache import load_pair

    root = tmp_path_factory.mktemp("folder_eval")
    dm = CompletionDataModule(data_dir=str(root / "data"), target_res=32, input_factor=4, prepare={"progress": False},
                              sizes={"train": 0, "val": 0, "test_same": 4, "test_cross": 0, "test_unseen": 0},
                              categories={"seen": ["chair", "table"]})
    dm.prepare_data()
    items = json.loads((root / "data" / "manifest.json").read_text())["items"]
    targets = {Path(it["file"]).stem: load_pair(root / "data" / it["file"])[1] for it in items}
    return root / "data", targets


def _run(argv, capsys) -> tuple[int, str]:
    code = eval_folder([str(a) for a in argv])
    return code, capsys.readouterr().err.strip()


def test_folder_of_grids_and_meshes_scores_perfect_copies(prepared, tmp_path, capsys):
    data, targets = prepared
    grids, meshes = tmp_path / "grids" / "test_same", tmp_path / "meshes"
    grids.mkdir(parents=True)
    meshes.mkdir()
    for k, (stem, tgt) in enumerate(targets.items()):
        if k % 2:
            np.save(grids / f"{stem}.npy", tgt.astype(np.float32))
        else:
            np.savez_compressed(grids / f"{stem}.npz", occupancy=tgt[None])
        verts, faces = grid_surface(tgt)
        if k % 2:  # the voxel frame: vertex (x, y, z) at grid index [x, y, z]
            verts = (verts + 0.5) * 32 - 0.5
        trimesh.Trimesh(verts, faces, process=False).export(meshes / f"{stem}.{'ply' if k % 2 else 'obj'}")
    code, err = _run([tmp_path / "grids", data, "--out", tmp_path / "out_grids"], capsys)
    assert code == 0, err
    m = json.loads((tmp_path / "out_grids" / "metrics.json").read_text())
    assert m["test/same/iou"] == 1.0 and m["test/same/chamfer_l1"] == 0.0 and m["test/same/fscore_1pct"] == 1.0
    assert m["splits"]["test_same"] == {"items": 4, "grid": 4, "mesh": 0}
    text = (tmp_path / "out_grids" / "results.md").read_text()
    assert "| grids (scored folder) | 1.000 | 0.0000 | 1.000 | 1.000 | 1.000 | 0 |" in text
    # meshes: some in the voxel frame, so score them in two runs of one frame each
    for frame, keep in (("unit", ".obj"), ("voxel", ".ply")):
        sub = tmp_path / f"meshes_{frame}"
        sub.mkdir()
        for f in meshes.glob(f"*{keep}"):
            f.rename(sub / f.name)
        for stem in targets:  # the others as grids, so every target has a prediction
            if not (sub / f"{stem}{keep}").exists():
                np.save(sub / f"{stem}.npy", targets[stem])
        code, err = _run([sub, data, "--out", tmp_path / f"out_{frame}", "--mesh-frame", frame], capsys)
        assert code == 0, err
        m = json.loads((tmp_path / f"out_{frame}" / "metrics.json").read_text())
        # the same surfaces (up to the files' float precision): distances ~1e-8, far below tau ~0.01
        assert m["test/same/chamfer_l1"] == pytest.approx(0.0, abs=1e-6) and m["test/same/fscore_1pct"] == 1.0
        assert "test/same/iou" not in m  # meshes have no IoU
        assert m["splits"]["test_same"] == {"items": 4, "grid": 2, "mesh": 2}


def test_folder_bad_inputs_one_line_exit_2(prepared, tmp_path, capsys):
    data, targets = prepared
    stems = sorted(targets)
    shape = targets[stems[0]].shape

    def folder(name, bad_name, write_bad):
        d = tmp_path / name
        d.mkdir()
        for s in stems[1:]:
            np.save(d / f"{s}.npy", targets[s])
        if write_bad is not None:
            write_bad(d / f"{stems[0]}{bad_name}")
        return d

    cases = {
        "missing": (folder("missing", "", None), f"missing prediction of the test_same target items/test_same/{stems[0]}.npz"),
        "shape": (folder("shape", ".npy", lambda p: np.save(p, np.zeros((16, 16, 16)))),
                  f"grid of shape (16, 16, 16), expected the target's {shape}"),
        "garbage": (folder("garbage", ".npz", lambda p: p.write_bytes(b"not a zip file at all")), "unreadable array file"),
        "empty": (folder("empty", ".obj", lambda p: p.write_bytes(b"")), "empty file"),
        "nan": (folder("nan", ".npy", lambda p: np.save(p, np.full(shape, np.nan))), "grid contains NaN or inf"),
        "range": (folder("range", ".npy", lambda p: np.save(p, np.full(shape, 3.0))), "expected occupancy in [0, 1]"),
        "nofaces": (folder("nofaces", ".obj", lambda p: p.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\n")), "no faces"),
    }
    for name, (pred, expected) in cases.items():
        code, err = _run([pred, data, "--out", tmp_path / f"out_{name}"], capsys)
        assert code == 2 and len(err.splitlines()) == 1, (name, err)
        assert err.startswith("lit3d-eval-folder: error: ") and expected in err, (name, err)
        named = f"{pred}/[test_same/]{stems[0]}" if name == "missing" else str(pred / stems[0])
        assert named in err, (name, err)  # names the file
        assert not (tmp_path / f"out_{name}").exists()  # nothing written, not even the folder
    code, err = _run([tmp_path / "shape", tmp_path / "nowhere", "--out", tmp_path / "o"], capsys)
    assert code == 2 and "no manifest.json" in err and str(tmp_path / "nowhere") in err
    (tmp_path / "afile").write_text("x")
    code, err = _run([tmp_path / "shape", data, "--out", tmp_path / "afile"], capsys)
    assert code == 2 and "--out is an existing file" in err
    # the console script's process: exit status 2 and one line, no traceback
    proc = subprocess.run([sys.executable, "-m", "lit3d.cli.eval_folder", str(tmp_path / "nan"), str(data),
                           "--out", str(tmp_path / "o2")], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and proc.stderr.strip().count("\n") == 0 and "NaN" in proc.stderr, proc.stderr


def test_folder_cli_help_and_version(capsys):
    from lit3d.cli.about import lit3d_version

    for flag in ("--help", "--version"):
        with pytest.raises(SystemExit) as exc:
            eval_folder([flag])
        assert exc.value.code == 0
    out = capsys.readouterr().out
    assert "against the targets of a prepared completion data split" in out
    assert out.count("    lit3d-eval-folder ") == 5  # five examples, two of them --targets
    assert "--targets TARGET_DIR" in out and "paired with" in out
    assert out.endswith(f"lit3d-eval-folder (lit3d) {lit3d_version()}\n")


def test_results_md_says_why_a_validation_iou_is_absent(tmp_path):
    text = write_results({"test/same/iou": 0.5, "test/threshold": 0.4, "val/iou": 0.546}, tmp_path).read_text()
    assert "Threshold chosen on validation: 0.40 (validation IoU 0.546)." in text
    text = write_results({"test/same/iou": 0.5, "test/threshold": 0.5}, tmp_path).read_text()
    assert "validation IoU –" not in text and "no validation IoU was measured for these weights" in text
