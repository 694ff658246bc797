"""What killed runs leave behind is removed by the next run.

A run killed outright (SIGKILL, the OOM killer, a power cut) cannot clean up after itself: an
evaluation leaves its hidden staging folder in the run dir, a checkpoint save its temp file beside
``last.ckpt``, an export its temp file beside the output, a data preparation the temp file of its
manifest. Before, nothing ever removed them: a killed ``lit3d-eval`` left ``.evaluation.*.tmp/`` in
a timestamped run dir that no later run visited. Now every temp and staging name carries its
writer's pid and host (:mod:`lit3d.utils.temp_names`); the next write of the same file removes the
temps of writers that are gone, and a run taking a run dir clears its own and those of the run
dirs beside it whose holder is gone (:mod:`lit3d.cli.run_leftovers`).

The real processes are killed at named points (``LIT3D_KILL_AT``, :mod:`lit3d.utils.kill_points`), so
each kill lands where the leftover is made, not wherever a signal happens to arrive.
"""
from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
from pathlib import Path

import pytest
from tests.helpers.completion import TINY_SIZES as SIZES, prepared_tiny_checkpoint
from tests.helpers.runs import BIN, REPO, TINY_NETS, child_env

from lit3d.cli.run_leftovers import clear_run_dirs
from lit3d.utils.io import atomic_write_text, write_json
from lit3d.utils.temp_names import HOST, tag, writer



def _dead_pid() -> int:
    """The pid of a process that has ended."""
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def _leftovers(folder: Path) -> list[str]:
    return sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.name.endswith(".tmp"))


# ----------------------------------------------------------------------------- in-process
def test_temp_names_say_who_wrote_them(tmp_path, monkeypatch):
    seen = []
    real = os.replace
    monkeypatch.setattr(os, "replace", lambda a, b: seen.append(Path(a).name) or real(a, b))
    atomic_write_text(tmp_path / "m.json", "{}")
    w = writer(seen[0])
    assert seen[0].startswith(f".m.json.{tag()}.") and w == (("m.json", os.getpid(), HOST))
    assert writer(".evaluation.123.abc_9.tmp") == ("evaluation", 123, None)  # the older names: the pid alone
    assert writer(".m.json.abc_9.tmp") is None


def test_the_next_write_of_a_file_removes_the_temps_killed_writers_left(tmp_path):
    dead = _dead_pid()
    stale = tmp_path / f".m.json.{dead}-{HOST}.k1.tmp"
    running = tmp_path / f".m.json.{os.getpid()}-{HOST}.k2.tmp"  # a writer that runs (this one)
    elsewhere = tmp_path / f".m.json.{dead}-ffffff.k3.tmp"  # another host's: its pid means nothing here
    other = tmp_path / f".n.json.{dead}-{HOST}.k4.tmp"  # another file's
    for p in (stale, running, elsewhere, other):
        p.write_text("half")
    write_json(tmp_path / "m.json", {"a": 1})
    assert json.loads((tmp_path / "m.json").read_text()) == {"a": 1}
    assert not stale.exists() and running.exists() and elsewhere.exists() and other.exists()


def _lock_file(run: Path, pid: int, host: str | None = None) -> None:
    run.mkdir(parents=True, exist_ok=True)
    (run / ".lit3d.lock").write_text(f"pid {pid} on {host or socket.gethostname()} since 2026-01-01 00:00:00\n")


def test_a_run_dir_clears_its_own_leftovers_and_those_of_killed_runs_beside_it(tmp_path):
    dead = _dead_pid()
    runs = tmp_path / "runs"
    own, killed, running, remote, finished = (runs / n for n in ("own", "killed", "running", "remote", "finished"))
    for run, pid, host in ((killed, dead, None), (running, os.getpid(), None), (remote, dead, "elsewhere")):
        _lock_file(run, pid, host)
        (run / "checkpoints").mkdir()
        (run / "checkpoints" / f".last.ckpt.{pid}-{HOST}.a.tmp").write_bytes(b"half")
        (run / f".evaluation.{pid}-{HOST}.b.tmp").mkdir()
        (run / f".evaluation.{pid}-{HOST}.b.tmp" / "metrics.json").write_text("{}")
    own.mkdir()
    (own / "checkpoints").mkdir()
    (own / "checkpoints" / ".last.ckpt.x1.tmp").write_bytes(b"half")  # an older temp name: no pid
    (own / f".config.yaml.{dead}-ffffff.c.tmp").write_text("half")
    finished.mkdir()  # a killed evaluation whose set was committed: its renames are finished
    (finished / ".lit3d.lock").write_text(f"pid {dead} on {socket.gethostname()} since 2026-01-01 00:00:00\n")
    stage = finished / f".evaluation.{dead}-{HOST}.d.tmp"
    stage.mkdir()
    (stage / "metrics.json").write_text('{"test/x": 1}\n')
    (stage / ".set.json").write_text(json.dumps({"files": ["metrics.json"], "pid": dead}))
    (tmp_path / "elsewhere").mkdir()  # not a run dir beside it: never looked at
    (tmp_path / "elsewhere" / f".x.{dead}-{HOST}.e.tmp").write_text("not ours to judge")

    notes = clear_run_dirs(own)
    assert _leftovers(own) == [] and _leftovers(killed) == [] and _leftovers(finished) == []
    assert (finished / "metrics.json").read_text() == '{"test/x": 1}\n'
    assert len(_leftovers(running)) == 2 and len(_leftovers(remote)) == 2  # a running run's, another host's
    assert (tmp_path / "elsewhere" / f".x.{dead}-{HOST}.e.tmp").exists()
    assert len(notes) == 5 and any("finished the set metrics.json" in n for n in notes), notes


# ----------------------------------------------------------------------------- real runs, killed
def _run(args: list[str], kill_at: str | None = None, timeout: float = 300) -> subprocess.CompletedProcess:
    env = child_env()
    env.pop("LIT3D_KILL_AT", None)
    if kill_at:
        env["LIT3D_KILL_AT"] = kill_at
    cmd = [str(BIN / args[0]), *args[1:]] if not args[0].startswith("-") else [sys.executable, *args]
    return subprocess.run(cmd, check=False, cwd=REPO, env=env, capture_output=True, text=True, timeout=timeout)


def _killed(res: subprocess.CompletedProcess) -> subprocess.CompletedProcess:
    assert res.returncode == -signal.SIGKILL, f"rc {res.returncode}\n{res.stderr[-3000:]}"
    return res


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory) -> Path:
    """An untrained tiny completion checkpoint whose data (prepared here) lit3d-eval evaluates."""
    return prepared_tiny_checkpoint(tmp_path_factory.mktemp("leftovers"))


@pytest.mark.slow
def test_killed_evaluations_leave_nothing_after_the_next_evaluation(tmp_path, checkpoint):
    """One evaluation killed while its files are staged, one killed during the renames of its set; each
    next ``lit3d-eval`` (into a run dir beside theirs, as the timestamped default gives) removes the
    staging folder of the first and finishes the set of the second, and evaluates."""
    runs = tmp_path / "eval"
    staged, renaming, nxt = runs / "a", runs / "b", runs / "c"
    _killed(_run(["lit3d-eval", f"ckpt_path={checkpoint}", f"hydra.run.dir={staged}"], "evaluation:staged"))
    assert [p.name.split(".")[1] for p in staged.glob(".*.tmp")] == ["evaluation"] and not (staged / "metrics.json").exists()
    res = _killed(_run(["lit3d-eval", f"ckpt_path={checkpoint}", f"hydra.run.dir={renaming}"], "file-set:committed"))
    assert f"note: {staged}/.evaluation." in res.stderr  # the run beside it is gone: its staging folder too
    assert _leftovers(staged) == [] and list(renaming.glob(".*.tmp")) and not (renaming / "metrics.json").exists()

    res = _run(["lit3d-eval", f"ckpt_path={checkpoint}", f"hydra.run.dir={nxt}"])
    assert res.returncode == 0, res.stderr[-3000:]
    assert _leftovers(runs) == []
    assert not (staged / "metrics.json").exists()  # staged, never committed: nothing of it is moved in
    assert json.loads((renaming / "metrics.json").read_text()) and (renaming / "results.md").is_file()
    assert json.loads((nxt / "metrics.json").read_text())
    assert f"note: {renaming}: finished the set" in res.stderr


@pytest.mark.slow
def test_a_checkpoint_save_killed_half_way_leaves_nothing_after_the_resume(tmp_path):
    run = tmp_path / "run"
    train = ["lit3d-train", "experiment=completion_demo", *TINY_NETS, SIZES, "data.batch_size=2", "data.prepare.progress=false",
             f"paths.data_dir={tmp_path}/data", "trainer.max_epochs=2", "logger=none", "callbacks.progress_bar=null",
             "callbacks.resume_state.every_n_train_batches=1", f"hydra.run.dir={run}"]
    _killed(_run(train, "write:last.ckpt@2"))  # the second save: the first one's last.ckpt is there
    assert [p.name.startswith(".last.ckpt.") for p in (run / "checkpoints").glob(".*.tmp")] == [True]
    res = _run([*train, "ckpt_path=last"])
    assert res.returncode == 0, res.stderr[-3000:]
    assert _leftovers(run) == [] and (run / "metrics.json").is_file()


@pytest.mark.slow
def test_a_killed_export_and_a_killed_preparation_leave_nothing_after_the_next(tmp_path, checkpoint):
    out = tmp_path / "model.pt"
    export = ["-c", f"import lit3d; lit3d.export(lit3d.load({str(checkpoint)!r}), {str(out)!r})"]
    _killed(_run(export, "write:model.pt"))
    assert [p.name.startswith(".model.pt.") for p in tmp_path.glob(".*.tmp")] == [True] and not out.exists()
    res = _run(export)
    assert res.returncode == 0, res.stderr[-3000:]
    assert out.is_file() and _leftovers(tmp_path) == []

    data = tmp_path / "data"
    prepare = ["lit3d-data", "experiment=completion_demo", SIZES, "data.prepare.progress=false", f"paths.data_dir={data}",
               f"hydra.run.dir={tmp_path}/run"]
    _killed(_run(prepare, "write:manifest.json"))
    assert len(list(data.rglob(".manifest.json.*.tmp"))) == 1 and not list(data.rglob("manifest.json"))
    res = _run(prepare)
    assert res.returncode == 0, res.stderr[-3000:]
    assert len(list(data.rglob("manifest.json"))) == 1 and _leftovers(tmp_path) == []
