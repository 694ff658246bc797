"""Ctrl-C (SIGINT) or SIGTERM while data is prepared stops at the next item.

Real ``lit3d-data`` / ``lit3d-train`` processes on a small synthetic completion set, the signal sent
once the first item is on disk:

- ``lit3d-data`` ran to the end (or ended in a traceback): now it stops at the next item with exit
  143 (as a stopped training) and one line ``error: <data_dir>: stopped by SIGINT (Ctrl-C) while
  preparing data (N of M items done); the same command again resumes``; the N items on disk are
  whole, no manifest is written, and the same command again makes only the missing ones;
- ``lit3d-train`` lost the Ctrl-C (Lightning resets its SIGTERM flag when training starts), trained
  every epoch and then printed a resume line for a stale ``last.ckpt``; two Ctrl-C ended in a
  traceback, SIGTERM killed it without a word. Now the preparation stops the same way: nothing is
  trained, no checkpoint, no resume line.

The signal is acted on also where the process was started with SIGINT ignored (a background job of a
non-interactive shell, as a test runner started with ``&``: there the old ``lit3d-data`` ran to the end
and exited 0), as ``lit3d-train``'s training handler always did. The stop points themselves
(:mod:`lit3d.utils.stops`) are checked in-process at the end.
"""
from __future__ import annotations

import re
import signal
import subprocess
from pathlib import Path

import pytest
from tests.helpers.runs import TINY_NETS
from tests.helpers.signals import signal_when, stop_line
from tests.helpers.runs import BIN, REPO, child_env, start_script

from datamodules.cache import MANIFEST, CacheBuilder
from datamodules.completion.voxel_cache import load_pair
from lit3d.utils import forced_exit
from lit3d.utils.stops import StopRequested, check_stop, on_signals, pending

DATA = ["experiment=completion_demo", "data.prepare.progress=false"]


def _sizes(train: int, rest: int = 0) -> str:
    return f"data.sizes={{train:{train},val:{rest},test_same:{rest},test_cross:{rest},test_unseen:{rest}}}"


def _items(data: Path) -> list[Path]:
    return sorted((data / "completion_demo" / "items").rglob("*.npz"))


def _stop_during_preparation(proc: subprocess.Popen, data: Path, log: Path, signals: list[int]) -> int:
    """Send ``signals`` (0.2 s apart) once the first item is on disk; the exit status."""
    return signal_when(proc, lambda: _items(data), log, signals)


def _line_pattern(data: Path, what: str, total: int) -> str:
    return (rf"error: {re.escape(str(data / 'completion_demo'))}: stopped by {re.escape(what)} while preparing "
            rf"data \((\d+) of {total} items done\); the same command again resumes")


def test_ctrl_c_stops_lit3d_data_at_the_next_item_and_the_same_command_resumes(tmp_path):
    data, log = tmp_path / "data", tmp_path / "data_cli"
    args = ["lit3d-data", *DATA, _sizes(10), f"paths.data_dir={data}", f"hydra.run.dir={tmp_path}/run"]
    rc = _stop_during_preparation(start_script(args, log), data, log, [signal.SIGINT])
    line = stop_line(log, rc)
    m = re.fullmatch(_line_pattern(data, "SIGINT (Ctrl-C)", 10), line)
    assert m, line
    done = _items(data)
    assert int(m.group(1)) == len(done) and 1 <= len(done) < 10, "stopped at the next item, the count is true"
    assert not (data / "completion_demo" / MANIFEST).exists(), "a stopped preparation wrote a manifest"
    assert not list(data.rglob("*.tmp")), "a half-written item was left"
    for p in done:
        load_pair(p)  # each item on disk is whole
    mtimes = {p: p.stat().st_mtime_ns for p in done}

    res = subprocess.run([str(BIN / args[0]), *args[1:]], cwd=REPO, env=child_env(), capture_output=True, text=True,
                         timeout=600)
    assert res.returncode == 0, res.stderr[-3000:]
    # log lines go to stderr: stdout holds the JSON summary alone
    assert f"{len(done)} of 10 items already prepared" in res.stderr
    assert {p: p.stat().st_mtime_ns for p in done} == mtimes, "the finished items were made again"
    assert len(_items(data)) == 10 and (data / "completion_demo" / MANIFEST).is_file()


@pytest.mark.parametrize("signals, what", [
    pytest.param([signal.SIGINT, signal.SIGINT], "SIGINT (Ctrl-C)", id="two_ctrl_c"),
    # the same path with the other signal (the in-process tests cover SIGTERM's handling): make test-all
    pytest.param([signal.SIGTERM], "SIGTERM", id="sigterm", marks=pytest.mark.slow)])
def test_lit3d_train_stops_while_preparing_without_training(tmp_path, signals, what):
    data, run, log = tmp_path / "data", tmp_path / "run", tmp_path / "train"
    args = ["lit3d-train", *DATA, _sizes(24, 2), "data.batch_size=4", *TINY_NETS, "trainer.max_epochs=1", "logger=csv",
            "callbacks.progress_bar=null", f"paths.data_dir={data}", f"hydra.run.dir={run}"]
    rc = _stop_during_preparation(start_script(args, log), data, log, signals)
    line = stop_line(log, rc)
    m = re.fullmatch(_line_pattern(data, what, 32), line)
    assert m and int(m.group(1)) == len(_items(data)) < 32, line
    err = log.with_suffix(".err").read_text()
    assert "ckpt_path=last" not in err and "resume with" not in err, "a resume line for a run that trained nothing"
    assert not (run / "checkpoints").exists(), "a checkpoint of an untrained run was written"
    assert not (run / "metrics.json").exists()
    assert not list(data.rglob("*.tmp"))


# ----------------------------------------------------------------------------- stop points, in-process
def test_stop_points_act_on_the_first_signal_and_name_the_folder(tmp_path):
    """The first signal is only recorded; the builder's next ``path()`` raises :class:`StopRequested`,
    which :meth:`CacheBuilder.prepare_once` labels with the folder and the items on disk; outside
    :func:`on_signals` nothing is recorded and the old handlers are back."""
    b = CacheBuilder(tmp_path / "cache", "test", "1", {"n": 3})
    written = []

    def write_items(builder):
        builder.total_items = 3
        for i in range(3):
            path = builder.path(f"items/{i}.bin")  # a stop point
            path.parent.mkdir(parents=True, exist_ok=True)
            if i == 1 and not written[2:]:  # the first run only
                signal.raise_signal(signal.SIGINT)  # a Ctrl-C while item 1 is made
                assert pending() == "SIGINT"
            path.write_bytes(b"x")
            written.append(i)
        return [{"file": f"items/{i}.bin"} for i in range(3)], {}

    before = signal.getsignal(signal.SIGINT)
    with on_signals(), pytest.raises(StopRequested) as info:
        b.prepare_once(write_items)
    assert written == [0, 1] and info.value.signame == "SIGINT"  # item 1 finished, item 2 never begun
    assert (info.value.where, info.value.done, info.value.total) == (b.root, 2, 3)
    assert not (b.root / MANIFEST).exists()
    assert signal.getsignal(signal.SIGINT) is before and pending() is None
    check_stop()  # outside on_signals: no stop pending, nothing raised
    assert b.prepare_once(write_items) and (b.root / MANIFEST).is_file()  # the rerun finishes it
    assert written == [0, 1, 0, 1, 2]


def test_a_second_signal_stops_at_once_and_later_ones_are_ignored():
    """A second signal raises :class:`StopRequested` where the program is; with ``ignore_after_stop``
    (the entry points) the signals are ignored after the stop, so a third Ctrl-C cannot break off the
    command's exit with a traceback."""
    before = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        with pytest.raises(StopRequested) as info, on_signals(ignore_after_stop=True):
            signal.raise_signal(signal.SIGTERM)  # recorded
            signal.raise_signal(signal.SIGINT)  # a second one: at once
            pytest.fail("the second signal did not stop at once")
        assert info.value.signame == "SIGTERM"  # the stop is named after the first signal
        # a handler that does nothing (not SIG_IGN: the commands' watcher still sees the signal and ends an
        # exit that hangs, lit3d.utils.forced_exit)
        assert signal.getsignal(signal.SIGINT) is signal.getsignal(signal.SIGTERM) is forced_exit.ignore
        signal.raise_signal(signal.SIGINT)  # ignored: no KeyboardInterrupt
    finally:
        for s, handler in before.items():
            signal.signal(s, handler)


def test_a_signal_after_the_last_stop_point_of_preparing_still_stops():
    """A Ctrl-C that comes after the last item's stop point (the data is complete) stops the command at the
    end of :func:`lit3d.cli.stops.preparing` instead of being forgotten (the command then trained on: seen
    once in CI, the Ctrl-C of test_ctrl_c_while_lit3d_train_starts_is_one_line not acted on)."""
    from lit3d.runtime.errors import Interrupted
    from lit3d.cli.stops import preparing

    before = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        with pytest.raises(Interrupted, match=r"data: stopped by SIGINT \(Ctrl-C\) while preparing data; the same"):
            with preparing("data"):
                signal.raise_signal(signal.SIGINT)  # recorded; no stop point follows
        with preparing("data"):  # no signal: the block ends as usual
            pass
    finally:
        for s, handler in before.items():
            signal.signal(s, handler)


def test_a_stopped_canonical_preparation_counts_its_subjects(tmp_path, monkeypatch):
    """The canonical data's stop line says "N of M items done" like the completion data's (M: the subjects)."""
    from datamodules.canonical import CanonicalDataModule

    dm = CanonicalDataModule.from_flat(str(tmp_path / "c"), image_size=32, n_subjects=3, n_poses=2, mesh_resolution=16, n_folds=2)
    render, calls = CanonicalDataModule._render_subject, []

    def render_then_ctrl_c(self, subject):
        calls.append(subject)
        if len(calls) == 2:
            signal.raise_signal(signal.SIGINT)  # a Ctrl-C while the second subject is rendered
        return render(self, subject)

    monkeypatch.setattr(CanonicalDataModule, "_render_subject", render_then_ctrl_c)
    with on_signals(), pytest.raises(StopRequested) as info:
        dm.prepare_data()
    n = len(dm.source.subjects())
    assert (info.value.done, info.value.total) == (2, n) and n > 2


@pytest.mark.parametrize("delay", [0.0, 1.0], ids=["at-the-run-dir-lock", "a-second-later"])
def test_ctrl_c_while_lit3d_train_starts_is_one_line(tmp_path, delay):
    """A Ctrl-C before any stage with its own stop (while the command claims its run dir, starts Hydra, imports
    Lightning, builds the model): one line and exit 143, no KeyboardInterrupt traceback (before: Python's)."""
    run, log = tmp_path / "run", tmp_path / "train"
    proc = start_script(["lit3d-train", "experiment=completion_demo", *TINY_NETS, "data.prepare.progress=false", "logger=none",
                   f"paths.data_dir={tmp_path}/data", f"hydra.run.dir={run}"], log)
    def locked():
        return (run / ".lit3d.lock").exists() and (delay == 0 or __import__("time").sleep(delay) is None)

    line = stop_line(log, signal_when(proc, locked, log, [signal.SIGINT]))
    assert line.startswith("error: ") and "stopped by SIGINT (Ctrl-C)" in line, line


def test_a_ctrl_c_swallowed_during_the_start_stops_the_first_stage():
    """A Ctrl-C of the command's start that a library swallows (raised inside a finaliser or a callback, where
    Python prints "Exception ignored" and goes on) is remembered: the first stage does not begin (before: the
    command trained on, the flake of test_ctrl_c_while_lit3d_train_starts_is_one_line under load)."""
    from lit3d.utils.stops import start_up

    before = signal.getsignal(signal.SIGINT)
    with start_up():
        try:
            signal.raise_signal(signal.SIGINT)
        except KeyboardInterrupt:
            pass  # what a swallowing library does
        with pytest.raises(KeyboardInterrupt):
            with on_signals():
                pytest.fail("the stage began after a Ctrl-C")
    assert signal.getsignal(signal.SIGINT) == before
    with on_signals():  # after the start: nothing remembered
        pass
