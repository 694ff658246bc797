"""lit3d-score --pairs: many pairs in one process, one table; bad pair lists end with one line."""
from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh

from lit3d.cli.score import main

FAST = ["--size", "48", "--styles", "toon", "--no-cache"]


@pytest.fixture
def shapes(tmp_path, monkeypatch):
    """refs/s<i>.obj and dists/s<i>.ply, i = 0, 1, 2 (more noise for a higher i), and pairs.tsv."""
    monkeypatch.setenv("LIT3D_CACHE", str(tmp_path / "cache"))
    (tmp_path / "refs").mkdir()
    (tmp_path / "dists").mkdir()
    for i in range(3):
        ref = trimesh.creation.icosphere(2)
        noise = np.random.default_rng(i).normal(0, 0.01 + 0.03 * i, (len(ref.vertices), 1))
        trimesh.Trimesh(ref.vertices + ref.vertex_normals * noise, ref.faces).export(tmp_path / "dists" / f"s{i}.ply")
        ref.export(tmp_path / "refs" / f"s{i}.obj")
    lines = ["reference\tdistorted", "# a comment, then an empty line", ""]
    lines += [f"refs/s{i}.obj\tdists/s{i}.ply" for i in range(3)]  # relative to the file's folder
    (tmp_path / "pairs.tsv").write_text("\n".join(lines) + "\n")
    return tmp_path


def test_tsv_gives_one_table_matching_single_calls(shapes, capsys):
    assert main(["--pairs", str(shapes / "pairs.tsv"), *FAST, "--json"]) == 0
    out, err = capsys.readouterr()
    doc = json.loads(out)
    scores = [p["overall_score"] for p in doc["pairs"]]
    assert [p["dist"] for p in doc["pairs"]] == [str(shapes / "dists" / f"s{i}.ply") for i in range(3)]
    assert scores[0] > scores[1] > scores[2]  # more noise, lower score
    assert [ln.split("]")[0] for ln in err.splitlines()] == ["[1/3", "[2/3", "[3/3"]  # a line per pair
    assert main([str(shapes / "refs" / "s1.obj"), str(shapes / "dists" / "s1.ply"), *FAST, "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["overall_score"] == pytest.approx(scores[1], abs=1e-6)
    # the markdown table: a header, a rule and one row per pair
    assert main(["--pairs", str(shapes / "pairs.tsv"), *FAST]) == 0
    table = capsys.readouterr().out.strip().splitlines()
    assert table[0].startswith("| # | reference | distorted | mean Mask-SSIM |") and len(table) == 5
    assert f"{scores[2]:.4f}" in table[4] and "chamfer" in table[0]


def test_two_folders_pair_files_by_name_stem(shapes, capsys):
    (shapes / "dists" / "extra.ply").write_bytes((shapes / "dists" / "s0.ply").read_bytes())
    assert main(["--pairs", str(shapes / "refs"), str(shapes / "dists"), *FAST, "--json"]) == 0
    out, err = capsys.readouterr()
    pairs = json.loads(out)["pairs"]
    assert [(p["ref"].rsplit("/", 1)[1], p["dist"].rsplit("/", 1)[1]) for p in pairs] == \
        [("s0.obj", "s0.ply"), ("s1.obj", "s1.ply"), ("s2.obj", "s2.ply")]
    assert "1 file(s) of" in err and "extra.ply" in err  # the unpaired file is named, not scored


def _bad_lists(root):
    """(arguments after --pairs, text the one-line error must hold)"""
    (root / "three.tsv").write_text("refs/s0.obj\tdists/s0.ply\textra\n")
    (root / "missing.tsv").write_text("refs/s0.obj\tdists/s0.ply\nrefs/nope.obj\tdists/s1.ply\n")
    (root / "empty.tsv").write_text("# nothing\n\n")
    (root / "binary.tsv").write_bytes(bytes(range(256)))
    (root / "lonely").mkdir()
    (root / "lonely" / "other.obj").write_text("v 0 0 0\n")
    (root / "twice").mkdir()
    for name in ("s0.obj", "s0.ply"):
        (root / "twice" / name).write_bytes((root / "refs" / "s0.obj").read_bytes())
    (root / "emptymesh").mkdir()
    (root / "emptymesh" / "s0.ply").write_bytes(b"")
    return [
        ([str(root / "nowhere.tsv")], "nowhere.tsv: no such file"),
        ([str(root / "three.tsv")], "three.tsv line 1: expected 2 tab-separated fields"),
        ([str(root / "missing.tsv")], f"missing.tsv line 2: {root / 'refs' / 'nope.obj'}: no such file"),
        ([str(root / "empty.tsv")], "empty.tsv: no pairs"),
        ([str(root / "binary.tsv")], "binary.tsv line 1: not a text file of pairs (a NUL byte)"),
        ([str(root / "refs")], "a folder; give a .tsv file"),
        ([str(root / "refs"), str(root / "dists"), str(root / "refs")], "got 3 arguments"),
        ([str(root / "refs"), str(root / "nodir")], "nodir: not a folder"),
        ([str(root / "refs"), str(root / "lonely")], "no file name stem is in both folders"),
        ([str(root / "twice"), str(root / "dists")], "s0.obj and s0.ply have the same stem"),
        ([str(root / "refs"), str(root / "emptymesh")], f"{root / 'emptymesh' / 's0.ply'}: empty file"),
    ]


def test_bad_pair_lists_end_with_one_line(shapes, capsys):
    for args, expected in _bad_lists(shapes):
        code = main(["--pairs", *args, *FAST])
        err = capsys.readouterr().err
        lines = [ln for ln in err.splitlines() if not ln.startswith(("[", "note: "))]  # progress lines, notes
        assert code == 2, (args, err)
        assert len(lines) == 1 and lines[0].startswith("lit3d-score: error: ") and expected in lines[0], (args, err)


@pytest.mark.parametrize("args, expected", [
    (["REF", "--pairs", "pairs.tsv"], "give no REF DIST with it"),
    (["--pairs", "pairs.tsv", "--save-views", "views"], "--save-views draws one pair"),
    ([], "give two shapes (REF DIST), or --pairs"),
])
def test_pairs_with_conflicting_options(shapes, capsys, args, expected):
    args = [str(shapes / a) if a in ("REF", "pairs.tsv", "views") else a for a in args]
    assert main([*args, *FAST]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and expected in err


@pytest.mark.timeout(60)  # a FIFO that were opened would block: fail, not hang
def test_fifo_folder_and_missing_file_have_one_wording(shapes, capsys):
    """A FIFO was an "empty file" for lit3d-score and "no such file" for --pairs, a folder "no such file":
    now every path is named for what it is, in the words of lit3d-reconstruct (lit3d.utils.files), and a
    FIFO is never opened."""
    import os

    os.mkfifo(shapes / "pipe.obj")
    os.mkfifo(shapes / "pipe.tsv")
    (shapes / "folder.obj").mkdir()
    fifo, folder, missing = shapes / "pipe.obj", shapes / "folder.obj", shapes / "gone.obj"
    ref = shapes / "refs" / "s0.obj"
    for name, bad in (("fifo.tsv", "pipe.obj"), ("folder.tsv", "folder.obj"), ("missing.tsv", "gone.obj")):
        (shapes / name).write_text(f"refs/s0.obj\tdists/s0.ply\nrefs/s1.obj\t{bad}\n")
    fifo_said, folder_said = "a named pipe (FIFO), not a regular file", "a folder, not a file"
    cases = [
        ([str(fifo), str(ref)], f"{fifo}: {fifo_said}"),
        ([str(ref), str(folder)], f"{folder}: {folder_said}"),
        ([str(ref), str(missing)], f"{missing}: no such file"),
        (["--pairs", str(shapes / "pipe.tsv")], f"{shapes / 'pipe.tsv'}: {fifo_said} (--pairs)"),
        (["--pairs", str(shapes / "fifo.tsv")], f"{shapes / 'fifo.tsv'} line 2: {fifo}: {fifo_said}"),
        (["--pairs", str(shapes / "folder.tsv")], f"{shapes / 'folder.tsv'} line 2: {folder}: {folder_said}"),
        (["--pairs", str(shapes / "missing.tsv")], f"{shapes / 'missing.tsv'} line 2: {missing}: no such file"),
    ]
    for args, expected in cases:
        assert main([*args, *FAST]) == 2, args
        err = [ln for ln in capsys.readouterr().err.splitlines() if not ln.startswith(("[", "note: "))]
        assert err == [f"lit3d-score: error: {expected}"], (args, err)


def test_a_byte_order_mark_and_a_latin1_name_in_a_pairs_file(shapes, capsys):
    """A UTF-8 BOM made the header a pair ('\\ufeffreference: no such file'); a Latin-1 file name made the
    whole file "not a text file" with no line number. Now the BOM is dropped, and the name is read byte
    for byte (surrogateescape): the file it names is scored, printed with \\xNN escapes."""
    import os

    bom = shapes / "bom.tsv"
    bom.write_bytes(b"\xef\xbb\xbfreference\tdistorted\r\nrefs/s0.obj\tdists/s0.ply\r\n")
    assert main(["--pairs", str(bom), *FAST, "--json"]) == 0
    pairs = json.loads(capsys.readouterr().out)["pairs"]
    assert [p["dist"] for p in pairs] == [str(shapes / "dists" / "s0.ply")]
    latin1 = os.fsencode(shapes / "dists") + b"/caf\xe9.ply"
    with open(shapes / "dists" / "s1.ply", "rb") as src, open(latin1, "wb") as dst:
        dst.write(src.read())
    (shapes / "latin1.tsv").write_bytes(b"# a Latin-1 name\nrefs/s1.obj\tdists/caf\xe9.ply\n")
    assert main(["--pairs", str(shapes / "latin1.tsv"), *FAST]) == 0
    out, err = capsys.readouterr()
    assert "caf\\xe9.ply" in out and "caf\\xe9.ply" in err
    (shapes / "gone.tsv").write_bytes(b"refs/s1.obj\tdists/gon\xe9.ply\n")
    assert main(["--pairs", str(shapes / "gone.tsv"), *FAST]) == 2
    assert capsys.readouterr().err.strip() == (f"lit3d-score: error: {shapes / 'gone.tsv'} line 1: "
                                               f"{shapes / 'dists'}/gon\\xe9.ply: no such file")
