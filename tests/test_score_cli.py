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


def test_ckpt_not_supported_yet(pair, capsys):
    ref, dist = pair
    assert main([str(ref), str(dist), *FAST, "--ckpt", "model.ckpt"]) != 0
    assert "not yet supported" in capsys.readouterr().err


def test_console_entry_point_subprocess(tmp_path):
    (tmp_path / "e.obj").write_bytes(b"")
    p = subprocess.run([sys.executable, "-m", "lit3d.cli.score", str(tmp_path / "e.obj"), str(tmp_path / "e.obj")],
                       capture_output=True, text=True, timeout=60)
    assert p.returncode == 2 and p.stderr.count("\n") == 1 and "e.obj: empty file" in p.stderr
