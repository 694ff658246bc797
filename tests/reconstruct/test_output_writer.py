"""Outputs never destroy inputs; every file-system and unit problem is one clear line.

Real bad files and folders written by the tests (tmp_path); each case checks the exit status,
the one line, that the user's input is unchanged and that nothing half-written is left. The
output checks of ``lit3d-reconstruct`` run before its checkpoint is loaded, so a stand-in
checkpoint file is enough here (the runs with a trained one are in test_reconstruct.py).
"""
from __future__ import annotations

import os
import stat
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from lit3d.cli import reconstruct as rec
from lit3d.reconstruct.depth_io import InputError, read_depth, read_depth_info
from lit3d.utils.io import OutputError, atomic_write_bytes, check_output_dir, unique_names, write_file_set
from tests.helpers.files import file_tree, write_depth_png






def _run(capsys, *argv) -> tuple[int, list[str]]:
    code = rec.main([str(a) for a in argv])
    err = capsys.readouterr().err
    return code, [ln for ln in err.splitlines() if ln.strip()]


@pytest.fixture
def fake_ckpt(tmp_path) -> Path:
    p = tmp_path / "model.ckpt"
    p.write_bytes(b"not loaded: the output checks come first")
    return p


# ------------------------------------------------------------------ the writer
def test_files_get_the_users_umask(tmp_path):
    old = os.umask(0o022)
    try:
        a = atomic_write_bytes(tmp_path / "a.bin", b"x")
        (s,) = write_file_set(tmp_path / "set", {"s.json": b"{}"})
    finally:
        os.umask(old)
    assert stat.S_IMODE(a.stat().st_mode) == 0o644
    assert stat.S_IMODE(s.stat().st_mode) == 0o644
    assert sorted(p.name for p in (tmp_path / "set").iterdir()) == ["s.json"]  # no temp folder left


def test_a_set_with_one_bad_name_writes_nothing(tmp_path):
    (tmp_path / "cow.json").mkdir()
    (tmp_path / "cow.obj").write_text("old")
    with pytest.raises(OutputError, match="cow.json: an output file of this name exists as a folder"):
        write_file_set(tmp_path, {"cow.obj": b"new", "cow.png": b"p", "cow.json": b"{}"})
    assert file_tree(tmp_path) == {"cow.json": None, "cow.obj": b"old"}


def test_set_refuses_to_replace_an_input(tmp_path):
    src = write_depth_png(tmp_path / "cow.png")
    before = src.read_bytes()
    with pytest.raises(OutputError, match="would replace the input"):
        write_file_set(tmp_path, {"cow.obj": b"m", "cow.png": b"picture"}, protected=[src])
    assert src.read_bytes() == before and sorted(file_tree(tmp_path)) == ["cow.png"]


def test_unique_names_keep_the_extension_then_the_folder():
    names, notes = unique_names(["d/a_cow.png", "d/a_cow.npy", "d/b.png"])
    assert names == ["a_cow_png", "a_cow_npy", "b"] and len(notes) == 2 and "a_cow_png" in notes[0]
    names, _ = unique_names(["x/scan.png", "y/scan.png", "x/scan.npy"])
    assert len(set(names)) == 3 and names[0] == "x_scan_png" and names[1] == "y_scan_png"
    assert unique_names(["p/Cow.png", "q/cow.png"])[0][0] != unique_names(["p/Cow.png", "q/cow.png"])[0][1]


def test_check_output_dir_one_line_per_problem(tmp_path, readonly_dir):
    f = tmp_path / "file.txt"
    f.write_text("keep")
    with pytest.raises(OutputError, match="is an existing file"):
        check_output_dir(f)
    with pytest.raises(OutputError, match="which is a file"):
        check_output_dir(f / "sub")
    with pytest.raises(OutputError, match="not writable"):
        check_output_dir(readonly_dir)
    with pytest.raises(OutputError, match="not writable"):
        check_output_dir(readonly_dir / "new")
    assert f.read_text() == "keep"


# ------------------------------------------------------------------ lit3d-reconstruct: file system
def test_reconstruct_refuses_out_that_would_replace_the_input(tmp_path, fake_ckpt, capsys):
    same = tmp_path / "same"
    src = write_depth_png(same / "cow.png")
    before = file_tree(same)
    code, lines = _run(capsys, src, "--ckpt", fake_ckpt, "--out", same)
    assert code == 2 and len(lines) == 1, lines
    assert lines[0].startswith("lit3d-reconstruct: error: ") and str(src) in lines[0]
    assert "would replace the input" in lines[0]
    assert file_tree(same) == before
    # --no-figure writes no .png: then the same folder is fine for the checks (the stand-in checkpoint fails next)
    code, lines = _run(capsys, src, "--ckpt", fake_ckpt, "--out", same, "--no-figure")
    assert code == 2 and "model.ckpt" in lines[-1]
    assert file_tree(same) == before


def test_reconstruct_refuses_an_out_that_is_a_file_or_read_only(tmp_path, fake_ckpt, readonly_dir, capsys):
    src = write_depth_png(tmp_path / "in" / "cow.png")
    a_file = tmp_path / "out.txt"
    a_file.write_text("mine")
    for out, words in ((a_file, "is an existing file"), (a_file / "sub", "which is a file"),
                       (readonly_dir, "not writable"), (readonly_dir / "new", "not writable")):
        before = file_tree(tmp_path)
        code, lines = _run(capsys, src, "--ckpt", fake_ckpt, "--out", out)
        assert code == 2 and len(lines) == 1 and words in lines[0] and str(out) in lines[0], lines
        assert "internal error" not in lines[0] and "model.ckpt" not in lines[0]  # before the checkpoint
        assert file_tree(tmp_path) == before


def test_reconstruct_refuses_an_output_name_taken_by_a_folder(tmp_path, fake_ckpt, capsys):
    src = write_depth_png(tmp_path / "in" / "cow.png")
    out = tmp_path / "out"
    (out / "cow_occupancy.npz").mkdir(parents=True)
    code, lines = _run(capsys, src, "--ckpt", fake_ckpt, "--out", out)
    assert code == 2 and len(lines) == 1 and "cow_occupancy.npz" in lines[0] and "folder" in lines[0], lines
    assert file_tree(out) == {"cow_occupancy.npz": None}


def test_reconstruct_refuses_fov_zero_and_bad_depth_scale(tmp_path, fake_ckpt, capsys):
    src = write_depth_png(tmp_path / "cow.png")
    for opt, val in (("--fov", "0"), ("--fov", "180"), ("--fov", "-5"), ("--depth-scale", "0")):
        code, lines = _run(capsys, src, "--ckpt", fake_ckpt, "--out", tmp_path / "out", opt, val)
        assert code == 2 and len(lines) == 1 and opt in lines[0], lines
    assert not (tmp_path / "out").exists()


def test_colliding_stems_and_repeated_inputs_are_named_apart(tmp_path, fake_ckpt, capsys):
    d = tmp_path / "d"
    write_depth_png(d / "a_cow.png")
    np.save(d / "a_cow.npy", np.ones((24, 32), np.float32))
    code, lines = _run(capsys, d, d / "a_cow.png", "--ckpt", fake_ckpt, "--out", tmp_path / "out")
    text = "\n".join(lines)
    assert "given more than once" in text and "a_cow_png" in text and "a_cow_npy" in text
    assert code == 2 and "model.ckpt" in lines[-1]  # the stand-in checkpoint is refused after the plan


# ------------------------------------------------------------------ units and values
def test_integer_npy_is_scaled_and_float_is_metres(tmp_path):
    mm = np.zeros((10, 12), np.uint16)
    mm[2:8, 3:9] = 1500
    np.save(tmp_path / "mm.npy", mm)
    depth, info = read_depth_info(tmp_path / "mm.npy", 0.001)
    assert depth.max() == pytest.approx(1.5) and info["units"].startswith("integer")
    assert info["depth_scale_applied"] == 0.001 and info["dtype"] == "uint16"
    np.save(tmp_path / "m.npy", mm.astype(np.float32) / 1000)
    depth, info = read_depth_info(tmp_path / "m.npy", 0.001)
    assert depth.max() == pytest.approx(1.5) and info["depth_scale_applied"] is None


def test_sensor_no_reading_is_background(tmp_path):
    d = np.full((10, 12), 65535, np.uint16)
    d[2:8, 3:9] = 800
    Image.fromarray(d).save(tmp_path / "holes.png")
    depth, info = read_depth_info(tmp_path / "holes.png")
    assert depth.max() == pytest.approx(0.8) and info["no_reading_pixels"] == 120 - 36
    Image.fromarray(np.full((10, 12), 65535, np.uint16)).save(tmp_path / "none.png")
    with pytest.raises(InputError, match="none.png: all background .*65535.*no reading"):
        read_depth(tmp_path / "none.png")


def test_tiny_array_is_reported_with_its_shape(tmp_path):
    np.save(tmp_path / "one.npy", np.ones((1, 1), np.float32))
    with pytest.raises(InputError, match=r"one.npy: depth image of shape \(1, 1\) is too small"):
        read_depth(tmp_path / "one.npy")
    np.save(tmp_path / "batch.npy", np.ones((1, 6, 7), np.float32))
    assert read_depth(tmp_path / "batch.npy").shape == (6, 7)


# ------------------------------------------------------------------ PLY colours (lit3d-score)
def _ply(path: Path, colours: np.ndarray, kind: str, binary: bool) -> Path:
    rng = np.random.default_rng(0)
    pts = rng.uniform(-1, 1, (len(colours), 3))
    head = ["ply", f"format {'binary_little_endian' if binary else 'ascii'} 1.0", f"element vertex {len(pts)}",
            "property float x", "property float y", "property float z",
            *(f"property {kind} {c}" for c in ("red", "green", "blue")), "end_header"]
    head_b = ("\n".join(head) + "\n").encode()
    if binary:
        cd = "u1" if kind == "uchar" else "<f4"
        rec_t = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("red", cd), ("green", cd), ("blue", cd)])
        rec = np.zeros(len(pts), rec_t)
        for i, c in enumerate("xyz"):
            rec[c] = pts[:, i]
        for i, c in enumerate(("red", "green", "blue")):
            rec[c] = colours[:, i]
        path.write_bytes(head_b + rec.tobytes())
    else:
        fmt = "%d" if kind == "uchar" else "%.6f"
        body = "\n".join(" ".join([*(f"{v:.6f}" for v in p), *(fmt % v for v in c)]) for p, c in zip(pts, colours))
        path.write_bytes(head_b + body.encode() + b"\n")
    return path


@pytest.mark.parametrize("binary", [False, True])
def test_ply_colours_are_read_by_their_declared_type(tmp_path, binary):
    from lit3d.render.point_clouds import load_points

    rgb8 = np.random.default_rng(1).integers(0, 256, (50, 3))
    a = load_points(_ply(tmp_path / "u8.ply", rgb8, "uchar", binary))
    b = load_points(_ply(tmp_path / "f.ply", (rgb8 / 255.0).astype(np.float32), "float", binary))
    np.testing.assert_allclose(a.colours, b.colours, atol=1e-6)
    assert 0.5 < float(b.colours.max()) <= 1.0  # not divided by 255 a second time


@pytest.mark.parametrize("binary", [False, True])
def test_nan_colours_are_refused_in_one_line(tmp_path, binary, capsys):
    from lit3d.cli import score

    col = np.full((50, 3), 0.5, np.float32)
    col[3, 1] = np.nan
    bad = _ply(tmp_path / "nan.ply", col, "float", binary)
    ok = _ply(tmp_path / "ok.ply", np.full((50, 3), 0.5, np.float32), "float", binary)
    before = file_tree(tmp_path)
    assert score.main([str(ok), str(bad), "--no-cache"]) == 2
    lines = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert len(lines) == 1 and str(bad) in lines[0] and "NaN" in lines[0], lines
    assert file_tree(tmp_path) == before


def test_data_cache_items_get_the_users_umask(tmp_path):
    from datamodules.cache import atomic_save_npz

    old = os.umask(0o022)
    try:
        p = atomic_save_npz(tmp_path / "items" / "a.npz", x=np.zeros(3))
    finally:
        os.umask(old)
    assert stat.S_IMODE(p.stat().st_mode) == 0o644
