"""``lit3d-reconstruct``'s output sets are whole, whatever stops the writer.

A real process writes a set over an earlier set of the same name (:func:`lit3d.utils.io.write_file_set`)
and is stopped half way through the renames (the test slows ``os.replace`` down there):

- Ctrl-C (SIGINT): the renames are finished, the new set is whole;
- SIGKILL: the staging folder keeps its journal; the next run (:func:`repair_sets`, which
  ``lit3d-reconstruct`` calls first) finishes the renames; a staging folder without a journal
  (killed while staging) is removed and the earlier set is left whole.

Then the CLI on a stand-in (untrained) checkpoint: a rerun skips a finished set (and removes a
stale staging folder), ``--overwrite`` or another option redoes it.
"""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from tests.helpers.runs import BIN, REPO, child_env
from tests.helpers.files import write_depth_png

OLD = {"x.obj": b"old mesh", "x_occupancy.npz": b"old grid", "x.png": b"old picture", "x.json": b"old summary"}
NEW = {k: v.replace(b"old", b"new") for k, v in OLD.items()}

# writes OLD, then NEW with os.replace (or the staging writes) slowed down after the first call
WRITER = """
import json, os, signal, sys, time
signal.signal(signal.SIGINT, signal.default_int_handler)  # Ctrl-C even where the suite runs as a background job
import lit3d.utils.io as io
out, where = sys.argv[1], sys.argv[2]
old = {k: v.encode() for k, v in json.loads(sys.argv[3]).items()}
new = {k: v.encode() for k, v in json.loads(sys.argv[4]).items()}
io.write_file_set(out, old)
real, stopped = (io.os.replace if where == "rename" else io.atomic_write_bytes), []
def slow(*a, **k):
    if where == "stage":  # before the journal is written
        print("stopping here", flush=True)
        time.sleep(60)
    r = real(*a, **k)
    if not stopped and os.path.dirname(str(a[1])) == out:  # after the first rename into place
        stopped.append(1)
        print("stopping here", flush=True)
        time.sleep(60)
    return r
if where == "rename":
    io.os.replace = slow
else:
    io.atomic_write_bytes = slow  # the journal's write: every file is staged, nothing committed
io.write_file_set(out, new)
"""


def _stop_writer(out: Path, where: str, sig: int) -> subprocess.Popen:
    as_text = [json.dumps({k: v.decode() for k, v in d.items()}) for d in (OLD, NEW)]
    proc = subprocess.Popen([sys.executable, "-c", WRITER, str(out), where, *as_text], cwd=REPO, env=child_env(),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "stopping here", proc.stderr.read()
    proc.send_signal(sig)
    proc.wait(timeout=60)
    return proc


def _files(out: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in out.iterdir() if p.is_file()}


def test_ctrl_c_during_the_renames_finishes_the_set(tmp_path):
    _stop_writer(tmp_path, "rename", signal.SIGINT)
    assert _files(tmp_path) == NEW and sorted(os.listdir(tmp_path)) == sorted(NEW)


@pytest.mark.parametrize("where, after", [("rename", NEW), ("stage", OLD)])
def test_sigkill_leaves_a_set_the_next_run_makes_whole(tmp_path, where, after):
    _stop_writer(tmp_path, where, signal.SIGKILL)
    staging = [p for p in tmp_path.iterdir() if p.is_dir()]
    assert len(staging) == 1 and staging[0].name.startswith(".x.obj.")
    if where == "rename":
        assert _files(tmp_path)["x.obj"] == NEW["x.obj"] and _files(tmp_path)["x.json"] == OLD["x.json"]  # mixed
    from lit3d.utils.io import repair_sets

    notes = repair_sets(tmp_path)
    assert len(notes) == 1 and ("finished the set" in notes[0]) == (where == "rename"), notes
    assert _files(tmp_path) == after and sorted(os.listdir(tmp_path)) == sorted(after)


@pytest.mark.slow  # default suite under 10 min; runs in make test-all
def test_rerun_skips_finished_sets_unless_overwrite(tmp_path):
    from lit3d.api.checkpoints import untrained_checkpoint

    ckpt = untrained_checkpoint("completion_demo", tmp_path / "c.ckpt", [
        "task.nets.latent_dim=64", "task.nets.k=16", "task.nets.fixed_latent_dim=64", "task.prior_samples=2"])
    src, out = write_depth_png(tmp_path / "in" / "cow.png"), tmp_path / "out"

    def cli(*extra: str) -> subprocess.CompletedProcess:
        res = subprocess.run([str(BIN / "lit3d-reconstruct"), str(src), "--ckpt", str(ckpt), "--out", str(out),
                              "--no-figure", *extra], cwd=REPO, env=child_env(), capture_output=True, text=True, timeout=300)
        assert res.returncode == 0, res.stderr[-3000:]
        return res

    cli()
    first = {p.name: p.stat().st_mtime_ns for p in out.iterdir()}
    stale = out / ".cow.obj.999999999.abcdefgh.tmp"  # a staging folder of a process that is gone
    stale.mkdir()
    (stale / "cow.obj").write_bytes(b"half")
    res = cli()
    assert "already reconstructed" in res.stderr and "removed the staging folder" in res.stderr
    assert not stale.exists() and {p.name: p.stat().st_mtime_ns for p in out.iterdir()} == first
    cli("--overwrite")
    assert (out / "cow.obj").stat().st_mtime_ns != first["cow.obj"]
    again = (out / "cow.json").stat().st_mtime_ns
    cli("--fov", "60")  # another option: another set
    assert (out / "cow.json").stat().st_mtime_ns != again
    assert json.loads((out / "cow.json").read_text())["intrinsics"]
