"""lit3d-score: summary, JSON, contact sheets, and one-line errors for bad shape files."""
from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
import trimesh

from lit3d.cli.score import main

FAST = ["--size", "64", "--styles", "toon,jade"]


@pytest.fixture
def pair(tmp_path, monkeypatch):
    monkeypatch.setenv("LIT3D_CACHE", str(tmp_path / "cache"))
    ref = trimesh.creation.icosphere(3)
    dist = ref.copy()
    dist.vertices = dist.vertices + dist.vertex_normals * np.random.default_rng(0).normal(0, 0.02, (len(ref.vertices), 1))
    ref.export(tmp_path / "ref.obj")
    dist.export(tmp_path / "dist.ply")
    return tmp_path / "ref.obj", tmp_path / "dist.ply"


def test_summary_and_json(pair, capsys, tmp_path):
    ref, dist = pair
    assert main([str(ref), str(dist), *FAST]) == 0
    out = capsys.readouterr().out
    assert "overall score (mean Mask-SSIM)" in out and "mask_ssim_window" in out and "chamfer" in out
    assert main([str(ref), str(dist), *FAST, "--json", "--save-views", str(tmp_path / "views")]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["cached"] is True  # second call hits the cache
    assert 0 < data["overall_score"] < 1
    assert "mask_ssim_negative/jade/smooth" in data["features"] and "hausdorff" in data["features"]
    assert (tmp_path / "views" / "contact_flat.png").is_file()


def test_voxel_npz_pair(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("LIT3D_CACHE", str(tmp_path / "cache"))
    x, y, z = np.mgrid[-1:1:24j, -1:1:24j, -1:1:24j]
    np.savez(tmp_path / "t.npz", arr_0=(x**2 + y**2 + z**2 < 0.5).astype(np.int8))
    np.savez(tmp_path / "p.npz", arr_0=(x**2 + 1.3 * y**2 + z**2 < 0.5).astype(np.int8))
    assert main([str(tmp_path / "t.npz"), str(tmp_path / "p.npz"), *FAST, "--json", "--no-cache"]) == 0
    assert json.loads(capsys.readouterr().out)["overall_score"] > 0


def _bad_files(tmp):
    (tmp / "empty.obj").write_bytes(b"")
    (tmp / "garbage.obj").write_bytes(bytes(range(256)) * 16)
    (tmp / "nofaces.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\n")
    (tmp / "nan.obj").write_text("v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n")
    (tmp / "adir.obj").mkdir()
    return ["empty.obj", "garbage.obj", "nofaces.obj", "nan.obj", "adir.obj", "missing.obj"]


def test_bad_inputs_one_line_no_traceback(pair, tmp_path, capsys):
    ref, _ = pair
    for name in _bad_files(tmp_path):
        bad = tmp_path / name
        code = main([str(ref), str(bad), *FAST])
        err = capsys.readouterr().err.strip()
        assert code != 0, name
        assert len(err.splitlines()) == 1 and str(bad) in err and "Traceback" not in err, (name, err)


def test_save_views_file_system_faults_one_line(pair, tmp_path, capsys):
    """--save-views that is a file, lies under one, is read-only, or would replace an input: exit 2,
    one line naming the path, before anything is rendered; nothing of the user's is changed."""
    import os
    import stat
    import subprocess as sp

    from tests.helpers.files import file_tree as _tree

    ref, dist = pair
    a_file = tmp_path / "notes.txt"
    a_file.write_text("mine")
    ro = tmp_path / "ro"
    ro.mkdir()
    mounted = False
    if os.geteuid() == 0:
        mounted = sp.run(["mount", "-t", "tmpfs", "-o", "ro,size=64k", "tmpfs", str(ro)],
                         capture_output=True).returncode == 0
    else:
        ro.chmod(0o555)
    clash = tmp_path / "clash"
    clash.mkdir()
    ref_in_out = clash / "contact_flat.png"  # an input with the name of a sheet
    ref_in_out.write_bytes(ref.read_bytes())
    cases = [([ref, dist], a_file, "is an existing file"), ([ref, dist], a_file / "v", "which is a file"),
             ([ref_in_out, dist], clash, "would replace the input")]
    if mounted or os.geteuid() != 0:
        cases.append(([ref, dist], ro / "views", "not writable"))
    try:
        for shapes, views, words in cases:
            before = _tree(tmp_path)
            code = main([*map(str, shapes), *FAST, "--no-cache", "--save-views", str(views)])
            lines = capsys.readouterr().err.strip().splitlines()
            assert code == 2 and len(lines) == 1 and words in lines[0], (views, lines)
            assert lines[0].startswith("lit3d-score: error: ") and "internal error" not in lines[0]
            assert _tree(tmp_path) == before
        # a good folder: the sheets, with the umask's mode, no temp folder left
        old = os.umask(0o022)
        try:
            assert main([str(ref), str(dist), *FAST, "--no-cache", "--save-views", str(tmp_path / "ok")]) == 0
        finally:
            os.umask(old)
        sheets = sorted((tmp_path / "ok").iterdir())
        assert [p.name for p in sheets] == ["contact_flat.png", "contact_smooth.png"]
        assert all(stat.S_IMODE(p.stat().st_mode) == 0o644 for p in sheets)
    finally:
        if mounted:
            sp.run(["umount", str(ro)], check=False)
        elif os.geteuid() != 0:
            ro.chmod(0o755)


# ---------------------------------------------------------------- --ckpt: a trained quality model
QUALITY_OPTIONS = {"size": 32, "styles": ["toon"], "measures": ["mask_ssim", "mse"], "n_samples": 500}


@pytest.fixture(scope="module")
def quality_ckpt(tmp_path_factory):
    """A quality checkpoint saved by ``lit3d-train``'s own ``train()`` (MetadataCallback included):
    3 procedural shapes x 2 distortions x 2 levels, 32 px renders of one style, SFS <= 2 features,
    2 epochs (about 5 s)."""
    from hydra import compose, initialize_config_dir
    from hydra.core.global_hydra import GlobalHydra
    from omegaconf import open_dict

    from lit3d.runtime.compose import CONF_DIR
    from lit3d.cli.train import train

    root = tmp_path_factory.mktemp("quality_ckpt")
    opts = ",".join(f"{k}:{v}" for k, v in QUALITY_OPTIONS.items()).replace("'", "")
    GlobalHydra.instance().clear()
    with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
        cfg = compose(config_name="train", overrides=[
            "experiment=quality_demo", "logger=none", "callbacks.progress_bar=null", "test_after_fit=false",
            "+trainer.enable_progress_bar=false", "data.synth.shapes=[blob,bumpy,torus]",
            "+data.synth.distortions=[noise,taubin]",
            "data.synth.n_levels=2", "data.synth.subdivisions=2", f"data.feature_tables.options={{{opts}}}", "task.sfs.epochs=2",
            "task.sfs.max_features=2", "evaluation.cv=false", "trainer.max_epochs=2"])
    GlobalHydra.instance().clear()
    with open_dict(cfg):
        cfg.paths.output_dir = str(root / "run")
        cfg.paths.data_dir = str(root / "data")
        cfg.paths.log_dir = str(root / "logs")
    train(cfg)
    return next((root / "run" / "checkpoints").glob("best-*.ckpt"))


def _edited(ckpt, out, edit):
    """A copy of ``ckpt`` with ``edit(dict)`` applied (plain torch.save, as Lightning writes it)."""
    import torch

    raw = torch.load(ckpt, map_location="cpu", weights_only=True)
    edit(raw)
    torch.save(raw, out)
    return out


def _by_hand(ckpt, features: dict) -> float:
    """The model's output for the selected columns of a feature table, via the task's own forward."""
    import torch

    from lit3d.quality.module import QualityTask

    task = QualityTask.load_from_checkpoint(ckpt, map_location="cpu").eval()
    x = torch.tensor([[features[f] for f in task.features]], dtype=torch.float32)  # (1, F)
    with torch.no_grad():
        return float(task(x)[0])


def test_ckpt_predicts_with_training_feature_options(pair, quality_ckpt, capsys, tmp_path):
    import torch

    from lit3d.callbacks.metadata import META_KEY
    from lit3d.quality import predict

    assert predict.META_KEY == META_KEY
    raw = torch.load(quality_ckpt, map_location="cpu", weights_only=True)
    selected = raw["quality"]["features"]
    assert raw[META_KEY]["task"]["name"] == "quality" and 1 <= len(selected) <= 2
    ref, dist = pair
    # --size/--styles differ from training: the checkpoint's options win, and the output says so
    assert main([str(ref), str(dist), "--size", "64", "--styles", "toon,jade", "--ckpt", str(quality_ckpt),
                 "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["config"]["render"]["size"] == 32 and data["config"]["styles"] == ["toon"]
    assert data["config"]["measures"] == ["mask_ssim", "mse"] and data["config"]["n_samples"] == 500
    assert any("--size 64 ignored" in n for n in data["notes"]) and any("--styles" in n for n in data["notes"])
    assert not any(k.startswith("mse/jade") for k in data["features"])
    src = data["score_source"]
    assert src["model"] == str(quality_ckpt) and src["features"] == selected and src["dataset"] == "synth"
    # synthetic data: ordinal severity on 0..1, higher = more distorted -> score = model output
    expected = _by_hand(quality_ckpt, data["features"])
    assert data["predicted_score"] == pytest.approx(expected, abs=1e-6)
    assert src["distortion"] == pytest.approx(expected, abs=1e-6) and src["score_range"] == [0.0, 1.0]
    # a MOS-like scale (0..10, higher = better) maps the output back: 10 * (1 - output)
    def mos(raw):
        raw["quality"]["scaling"] = {"lo": 0.0, "hi": 10.0, "higher_is_better": True, "name": "MOS"}
    mos_ckpt = _edited(quality_ckpt, tmp_path / "mos.ckpt", mos)
    assert main([str(ref), str(dist), "--ckpt", str(mos_ckpt)]) == 0
    out = capsys.readouterr().out
    line = next(ln for ln in out.splitlines() if ln.startswith("predicted quality"))
    assert line == f"predicted quality (model {mos_ckpt}): {10 * (1 - expected):.4f}"
    assert "range 0..10, higher = better" in out and "note:" not in out


def test_ckpt_refuses_other_tasks_and_non_checkpoints(pair, quality_ckpt, capsys, tmp_path):
    import torch

    ref, dist = pair

    def canonical(raw):  # what a canonical-task checkpoint carries: lit3d metadata, no quality entry
        raw["lit3d"]["task"] = {"_target_": "lit3d.canonical.module.CanonicalTask", "name": "canonical"}
        del raw["quality"]

    def renamed(raw):  # a selected feature the checkpoint's options do not render
        raw["quality"]["features"][0] = "mse/jade/flat"

    def custom_features(raw):  # trained on a custom feature function, not the renderer's table
        raw["lit3d"]["data"]["feature_fn"] = "tests.helpers.quality.fake_features"

    (tmp_path / "notes.ckpt").write_text("not a checkpoint\n")
    torch.save({"state_dict": {}, "epoch": 3}, tmp_path / "plain.ckpt")
    cases = {
        _edited(quality_ckpt, tmp_path / "canonical.ckpt", canonical):
            "checkpoint is a canonical model, expected a quality model",
        _edited(quality_ckpt, tmp_path / "custom.ckpt", custom_features): "features of data.feature_tables.fn=",
        tmp_path / "notes.ckpt": "not a readable checkpoint",
        tmp_path / "plain.ckpt": "not a lit3d quality checkpoint",
        tmp_path / "missing.ckpt": "checkpoint not found",
        _edited(quality_ckpt, tmp_path / "renamed.ckpt", renamed): "lacks 1 of the",
    }
    for path, msg in cases.items():
        code = main([str(ref), str(dist), "--ckpt", str(path)])
        err = capsys.readouterr().err
        assert code == 2, (path, err)
        assert err.count("\n") == 1 and err.startswith(f"lit3d-score: error: {path}: ") and msg in err, err


def test_console_entry_point_subprocess(tmp_path):
    (tmp_path / "e.obj").write_bytes(b"")
    p = subprocess.run([sys.executable, "-m", "lit3d.cli.score", str(tmp_path / "e.obj"), str(tmp_path / "e.obj")],
                       capture_output=True, text=True, timeout=60)
    assert p.returncode == 2 and p.stderr.count("\n") == 1 and "e.obj: empty file" in p.stderr


def test_pairs_with_ckpt_predict_each_pair(pair, quality_ckpt, capsys, tmp_path):
    """--pairs --ckpt: the model's options and prediction for every pair, as for the pair alone."""
    ref, dist = pair
    (tmp_path / "pairs.tsv").write_text(f"{ref.name}\t{dist.name}\n{ref.name}\t{ref.name}\n")
    assert main(["--pairs", str(tmp_path / "pairs.tsv"), "--ckpt", str(quality_ckpt), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["config"]["render"]["size"] == 32 and len(doc["pairs"]) == 2
    assert main([str(ref), str(dist), "--ckpt", str(quality_ckpt), "--json"]) == 0
    alone = json.loads(capsys.readouterr().out)
    assert doc["pairs"][0]["predicted_score"] == pytest.approx(alone["predicted_score"], abs=1e-6)
    assert main(["--pairs", str(tmp_path / "pairs.tsv"), "--ckpt", str(quality_ckpt)]) == 0
    assert "| mean Mask-SSIM | predicted |" in capsys.readouterr().out
