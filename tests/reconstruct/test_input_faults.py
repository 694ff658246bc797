"""Inputs that were paired, read or reported wrongly.

Real files written by the tests (multi-page TIFF, FIFO, misnamed numpy files, a 20000x9000 PNG,
mask folders, symlinks, read-only and full file systems). ``lit3d-reconstruct`` runs in process
with a stand-in completer (its network output is empty; the visible voxels make the mesh), so
the whole CLI path (inputs, masks, JSON, exit status, the one line) runs in seconds; SIGTERM is
sent to a real process. ``lit3d-score`` runs in process on two small meshes at 16 px.
"""
from __future__ import annotations

import errno
import json
import os
import signal
import struct
import subprocess
import sys
import zlib
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from tests.helpers.runs import REPO, child_env
from tests.helpers.files import write_depth_png

from lit3d.cli import reconstruct as rec
from lit3d.reconstruct.depth_io import InputError, read_depth
from lit3d.reconstruct.grid import GridGeometry

RES = 16


class _Completer:
    """Stand-in for a loaded completion checkpoint: predicts nothing (the fused visible voxels
    make the mesh)."""

    notes: list = []
    threshold, path, device = 0.5, "stand-in.ckpt", "cpu"
    geometry = GridGeometry("synth", RES, 2, 1.0, 0.0)

    def probabilities(self, partial: np.ndarray) -> np.ndarray:
        return np.zeros((RES,) * 3, np.float32)


@pytest.fixture
def cli(tmp_path, monkeypatch, capsys):
    """``cli(*argv) -> (exit status, stderr lines)`` of lit3d-reconstruct with the stand-in completer."""
    import lit3d.reconstruct.pipeline as pipeline

    monkeypatch.setattr(pipeline, "load_completer", lambda path, device="cpu": _Completer())
    ckpt = tmp_path / "stand-in.ckpt"
    ckpt.write_bytes(b"never loaded")

    def run(*argv) -> tuple[int, list[str]]:
        code = rec.main([*map(str, argv), "--ckpt", str(ckpt), "--no-figure"])
        return code, [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    return run


def _errors(lines: list[str]) -> list[str]:
    return [ln for ln in lines if "error" in ln]


# ------------------------------------------------------------------ fault 6: mask pairing
def _mask(path: Path, cols: slice) -> Path:
    m = np.zeros((24, 32), np.uint8)
    m[6:18, cols] = 255
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(m).save(path)
    return path


def test_mask_folder_pairs_by_exact_stem_and_the_json_names_it(tmp_path, cli):
    src, masks = tmp_path / "in", tmp_path / "masks"
    write_depth_png(src / "scan[1].png")
    write_depth_png(src / "cow.png")
    _mask(masks / "scan1.png", slice(8, 12))      # what the glob pattern scan[1].* matched
    _mask(masks / "scan[1].png", slice(8, 20))    # scan[1]'s own mask
    _mask(masks / "cow.png", slice(8, 14))
    (masks / "cow.json").write_text("{}")         # sorts before cow.png; not a mask
    code, lines = cli(src, "--mask", masks, "--out", tmp_path / "out")
    assert code == 0, lines
    for name, mask, pixels in (("scan[1]", "scan[1].png", 12 * 12), ("cow", "cow.png", 12 * 6)):
        summary = json.loads((tmp_path / "out" / f"{name}.json").read_text())
        assert summary["mask"] == str(masks / mask)
        assert summary["counts"]["object_pixels"] == pixels

    (masks / "scan[1].png").unlink()  # only scan1.png is left: no mask for scan[1], one line
    code, lines = cli(src / "scan[1].png", "--mask", masks, "--out", tmp_path / "out2")
    assert code == 2 and len(_errors(lines)) == 1, lines
    assert "scan[1].png: no mask" in lines[-1] and "masks/scan[1].<png|" in lines[-1]
    assert not (tmp_path / "out2" / "scan[1].json").exists()


# ------------------------------------------------------------------ fault 8: multi-page TIFF
def test_multi_page_tiff_is_refused_with_its_page_count(tmp_path, cli):
    pages = [np.full((24, 32), 1000 + 100 * k, np.uint16) for k in range(3)]
    tif = tmp_path / "stack.tif"
    Image.fromarray(pages[0]).save(tif, save_all=True, append_images=[Image.fromarray(p) for p in pages[1:]])
    assert Image.open(tif).n_frames == 3
    code, lines = cli(tif, "--out", tmp_path / "out")
    assert code == 2 and len(_errors(lines)) == 1, lines
    assert lines[-1] == (f"lit3d-reconstruct: error: {tif}: 3 pages (a multi-page TIFF); one depth image per "
                         "file is read: save each page as its own file")
    assert not list((tmp_path / "out").glob("stack*"))
    Image.fromarray(pages[1]).save(tmp_path / "one.tif")  # one page: read as before
    assert read_depth(tmp_path / "one.tif").max() == pytest.approx(1.1)


# ------------------------------------------------------------------ fault 17: the optional score cache
def _meshes(folder: Path) -> tuple[Path, Path]:
    import trimesh

    a, b = folder / "a.obj", folder / "b.obj"
    trimesh.creation.box().export(a)
    trimesh.creation.icosphere(1).export(b)
    return a, b


def _score(capsys, monkeypatch, folder: Path, cache: Path, *extra: str) -> tuple[int, str, list[str]]:
    """lit3d-score of a box and a sphere written into ``folder``, the cache under ``cache``."""
    from lit3d.cli import score

    monkeypatch.setenv("LIT3D_CACHE", str(cache))
    a, b = _meshes(folder)
    code = score.main([str(a), str(b), "--size", "16", "--styles", "jade", *extra])
    out, err = capsys.readouterr()
    return code, out, [ln for ln in err.splitlines() if ln.strip()]


@pytest.fixture
def full_dir(tmp_path):
    """A folder on a full file system: a 64 kB tmpfs filled up (root only; skipped elsewhere)."""
    d = tmp_path / "full"
    d.mkdir()
    if os.geteuid() != 0 or subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(d)],
                                           capture_output=True).returncode != 0:
        pytest.skip("cannot mount a small tmpfs to fill (needs root)")
    try:
        with pytest.raises(OSError) as full, open(d / "filler", "wb") as f:
            while True:
                f.write(b"\0" * 4096)
                f.flush()
        assert full.value.errno == errno.ENOSPC
        (d / "features").mkdir()  # a folder still fits; the cached table does not
        yield d
    finally:
        subprocess.run(["umount", str(d)], check=False)


@pytest.mark.parametrize("disk, problem", [("under_a_file", "a parent of it is a file, not a folder"),
                                           ("readonly_dir", "read-only file system"),
                                           ("full_dir", "no space left on the device")])
def test_score_cache_that_cannot_be_written_warns_and_scores(tmp_path, capsys, monkeypatch, request, disk, problem):
    if disk == "under_a_file":  # needs no root: a cache folder that cannot be made
        (tmp_path / "file").write_text("a file, not a folder")
        cache = tmp_path / "file" / "cache"
    else:
        cache = request.getfixturevalue(disk)
    code, out, err = _score(capsys, monkeypatch, tmp_path, cache)
    assert code == 0, err
    assert "overall score (mean Mask-SSIM):" in out.splitlines()[-1]
    assert err == [f"lit3d-score: warning: feature cache not written: {cache / 'features'}: cannot write here "
                   f"({problem}); the score is computed but not cached (--no-cache skips the cache, "
                   "LIT3D_CACHE=DIR moves it)"]


# ------------------------------------------------------------------ fault 18: resource limits
def _huge_png(path: Path, width: int = 20000, height: int = 9000) -> Path:
    """A valid 1-bit PNG of width x height (all black): about 22 kB on disk."""
    def chunk(tag: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data))

    z, row = zlib.compressobj(9), b"\0" * (1 + (width + 7) // 8)  # filter byte + packed bits
    idat = b"".join(z.compress(row * 1000) for _ in range(height // 1000)) + z.compress(row * (height % 1000))
    ihdr = struct.pack(">IIBBBBB", width, height, 1, 0, 0, 0, 0)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", idat + z.flush()) + chunk(b"IEND", b""))
    return path


def test_a_huge_png_is_one_line_naming_the_file_and_the_limit(tmp_path, cli):
    big = _huge_png(tmp_path / "big.png")
    assert big.stat().st_size < 100_000
    code, lines = cli(big, "--out", tmp_path / "out")
    assert code == 2 and len(_errors(lines)) == 1, lines
    assert lines[-1] == (f"lit3d-reconstruct: error: {big}: image of 180,000,000 pixels, over the reader's limit "
                         "of 178,956,970 (Pillow's decompression-bomb guard); crop or downscale it")


def test_score_size_that_cannot_be_allocated_is_one_line(tmp_path, capsys, monkeypatch):
    import torch

    import lit3d.features.table as table

    def allocate(*args, **kwargs):  # a table too large for this machine, failing as torch fails
        return torch.empty(1 << 40, dtype=torch.uint8)

    monkeypatch.setattr(table, "feature_table", allocate)
    code, out, err = _score(capsys, monkeypatch, tmp_path, tmp_path / "cache", "--size", "4096")
    assert code == 2 and not out and err == [
        "lit3d-score: error: --size 4096: not enough memory (tried to allocate 1.00 TiB) for renders of 4096 px; "
        "try a smaller --size (default 256)"], err


# ------------------------------------------------------------------ fault 19: misleading lines
def test_a_fifo_is_named_as_a_fifo(tmp_path, cli):
    fifo = tmp_path / "pipe.png"
    os.mkfifo(fifo)
    code, lines = cli(fifo, "--out", tmp_path / "out")
    assert code == 2 and lines[-1] == (f"lit3d-reconstruct: error: {fifo}: a named pipe (FIFO), not a regular "
                                       "file; give an image or array file"), lines


def test_numpy_files_are_read_by_content_not_suffix(tmp_path, cli):
    depth = np.zeros((24, 32), np.float32)
    depth[6:18, 8:24] = 1.5
    np.savez(tmp_path / "a.npz", depth=depth)
    os.replace(tmp_path / "a.npz", tmp_path / "archive.npy")   # an .npz archive named .npy
    np.save(tmp_path / "b.npy", depth)
    os.replace(tmp_path / "b.npy", tmp_path / "array.npz")     # an .npy array named .npz
    for p in ("archive.npy", "array.npz"):
        np.testing.assert_array_equal(read_depth(tmp_path / p), depth)
    code, lines = cli(tmp_path / "archive.npy", tmp_path / "array.npz", "--out", tmp_path / "out")
    assert code == 0 and not _errors(lines), lines
    assert {p.name for p in (tmp_path / "out").glob("*.json")} == {"archive.json", "array.json"}


@pytest.mark.parametrize("via_link", [True, False])
def test_out_that_is_the_input_folder_is_refused(tmp_path, cli, via_link):
    src = tmp_path / "in"
    src.mkdir()
    np.save(src / "cow.npy", np.full((24, 32), 1.5, np.float32))
    out = tmp_path / "link" if via_link else src
    if via_link:
        out.symlink_to(src, target_is_directory=True)
    code, lines = cli(src, "--out", out)
    assert code == 2 and len(lines) == 1, lines
    assert lines[0].startswith(f"lit3d-reconstruct: error: {out}: --out is the input folder {src}")
    assert ("through the link" in lines[0]) == via_link and "a rerun would read the outputs" in lines[0]
    assert sorted(p.name for p in src.iterdir()) == ["cow.npy"]
    code, lines = cli(src, "--out", src / "out")  # a subfolder is fine: a folder input is not read recursively
    assert code == 0 and (src / "out" / "cow.json").is_file(), lines


# the CLI in a real process, its completer and per-image work stood in for (no torch: starts in
# about a second): the image named on the command line sleeps, so the test can stop the batch there
STOPPABLE = """
import sys, time
import lit3d.reconstruct.pipeline as pipeline
from lit3d.cli import reconstruct as rec
from lit3d.reconstruct.outputs import request_key, write_outputs
pipeline.load_completer = lambda path, device="cpu": type("Stub", (), {"notes": []})()
def one(args, path, name, completer, mapper, scorer, protected):
    if path.name == sys.argv[1]:
        print("stopping here", flush=True)
        time.sleep(60)
    files = {".obj": b"mesh", "_occupancy.npz": b"grid"}
    write_outputs(args.out, name, files, {"input": str(path), "request": request_key(args, path)}, protected)
    return {"timings_s": {"total": 0.0}}
rec._one = one
sys.exit(rec.main(sys.argv[2:]))
"""


def test_sigterm_says_what_was_kept_and_a_rerun_skips_it(tmp_path):
    src, out = tmp_path / "in", tmp_path / "out"
    src.mkdir()
    for i in range(5):
        np.save(src / f"s{i}.npy", np.full((24, 32), 1.5, np.float32))

    def start(stop_at: str) -> subprocess.Popen:
        return subprocess.Popen([sys.executable, "-c", STOPPABLE, stop_at, str(src), "--ckpt", str(src / "s0.npy"),
                                 "--out", str(out), "--no-figure"], cwd=REPO, env=child_env(), text=True,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE)

    proc = start("s2.npy")
    assert proc.stdout.readline().strip() == "stopping here", proc.stderr.read()
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    lines = [ln for ln in err.replace("\r", "\n").splitlines() if ln.startswith("lit3d-reconstruct")]
    assert proc.returncode == 143, err
    assert lines[-1] == (f"lit3d-reconstruct: stopped by SIGTERM at image 3 of 5: the 2 finished sets in {out} "
                         f"are whole and kept; {src / 's2.npy'} (in progress) was not written; the same command "
                         "again does the rest (finished sets are skipped)"), err
    kept = {p.name: p.stat().st_mtime_ns for p in out.iterdir()}
    assert sorted(kept) == sorted(f"s{i}{s}" for i in (0, 1) for s in (".json", ".obj", "_occupancy.npz"))

    proc = start("none")
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 0, err
    assert "5 of 5 images reconstructed" not in err and "2 already there skipped" in err, err
    assert all(out.joinpath(n).stat().st_mtime_ns == t for n, t in kept.items())
    assert len(list(out.glob("*.json"))) == 5


def test_bad_paths_are_named_for_what_they_are(tmp_path):
    (tmp_path / "dir.png").mkdir()
    (tmp_path / "dangling.png").symlink_to(tmp_path / "gone.png")
    for name, what in (("dir.png", "a folder, not a file"), ("dangling.png", "broken symbolic link"),
                       ("nothing.png", "no such file")):
        with pytest.raises(InputError, match=what):
            read_depth(tmp_path / name)


def test_float_millimetres_are_refused_as_a_unit_mistake(tmp_path, cli):
    """Float depth is metres; float millimetres (a person at 2800) were read as 2.8 km: the body fit wrote a
    person 2.8 km away with only a "poor fit" warning, the completion an object as far. Now one line names
    the file, the median and the fix; float metres and integer millimetres of the same scene are read."""
    depth = np.zeros((24, 32), np.float32)
    depth[6:18, 8:24] = 2.8
    np.save(tmp_path / "metres.npy", depth)
    np.save(tmp_path / "millimetres.npy", depth * 1000)
    code, lines = cli(tmp_path / "millimetres.npy", tmp_path / "metres.npy", "--out", tmp_path / "out")
    assert code == 2 and _errors(lines)[0] == (
        f"lit3d-reconstruct: error: {tmp_path / 'millimetres.npy'}: float depth is read as metres, and the depth's "
        "median is 2800 m, more than 100 m (millimetres?); float depth must be metres: divide by 1000, or save "
        "integer millimetres (a uint16 PNG or .npy)"), lines
    assert (tmp_path / "out" / "metres.obj").is_file() and not (tmp_path / "out" / "millimetres.obj").exists()
    with pytest.raises(InputError, match=r"depth_scale 1 m, and the depth's median is 2800 m"):
        from lit3d.reconstruct.depth_io import depth_from_array
        depth_from_array(np.round(depth * 1000).astype(np.uint16), "d.npy", depth_scale=1.0)
