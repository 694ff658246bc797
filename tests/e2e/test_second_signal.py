"""A second Ctrl-C (or SIGTERM) ends a command within 2 s (lit3d.utils.forced_exit).

Small real processes (``python -c`` programs using the commands' signal handling) are stopped with real
signals: before, a program busy in its clean stop, or inside one long native call, acted on the second
signal only when that work ended (``lit3d-reconstruct --body`` during the first Anny cache build: 44-65 s
after SIGTERM). Now: exit 130 (SIGINT) / 143 (SIGTERM) within 2 s of the second signal, one line, and
no temp file of an unfinished write left in the output folder. Inside a native step (the Anny cache
build) the first signal already does so. The in-process tests at the end check the pieces of the Anny
cache's first build (lit3d.body_model.anny_cache): its lines, silence when cached, the part-written files it removes.
"""
from __future__ import annotations

import json
import os
import signal
import struct
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from lit3d.utils import progress as progress_module
from tests.helpers.paths import REPO

LIMIT_S = 2.0  # from the signal that forces the exit to the process's end

PRELUDE = """
import hashlib, os, signal, sys, threading, time
from pathlib import Path
from lit3d.utils import forced_exit
from lit3d.utils.io import atomic_file
from lit3d.utils.stops import StopRequested, check_stop, on_signals
out = Path(sys.argv[1])

def native_call():
    # one long C call that releases the GIL and is not broken off by signals (as a torch op):
    # Python's handlers cannot run until it returns, minutes later
    hashlib.pbkdf2_hmac("sha256", b"x", b"y", 10**9)

def ready_inside(name):
    # print "ready" once the main thread runs the function ``name`` (a first signal sent before would not test it)
    main = threading.main_thread().ident
    def say():
        while sys._current_frames()[main].f_code.co_name != name:
            time.sleep(0.01)
        time.sleep(0.2)
        print("ready", flush=True)
    threading.Thread(target=say, daemon=True).start()
"""


def _start(tmp_path: Path, program: str, **kw) -> subprocess.Popen:
    code = PRELUDE + textwrap.dedent(program)
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    return subprocess.Popen([sys.executable, "-c", code, str(tmp_path)], cwd=REPO, env=env, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, **kw)


def _wait_for(proc: subprocess.Popen, word: str) -> None:
    """Read stdout until a line ``word`` (the program says where it is)."""
    for line in proc.stdout:
        if line.strip() == word:
            return
    raise AssertionError(f"ended (rc {proc.wait()}) before '{word}':\n{proc.stderr.read()[-3000:]}")


def _ends_within(proc: subprocess.Popen, limit: float = LIMIT_S) -> tuple[int, float, list[str]]:
    """(exit status, seconds to the end, stderr lines) of a process just signalled; killed past 30 s."""
    t0 = time.monotonic()
    try:
        rc = proc.wait(timeout=30)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
        raise AssertionError(f"still running 30 s after the signal:\n{proc.stderr.read()[-3000:]}") from None
    took = time.monotonic() - t0
    lines = [ln for ln in proc.stderr.read().splitlines() if ln.strip()]
    return rc, took, lines


def _stop_twice(proc: subprocess.Popen, first: int, second: int, ready_again: str | None = None):
    _wait_for(proc, "ready")
    proc.send_signal(first)
    if ready_again:
        _wait_for(proc, ready_again)
    else:
        time.sleep(0.3)
    proc.send_signal(second)
    return _ends_within(proc)


SLOW_CLEAN_STOP = """
with forced_exit.watching():
    try:
        with on_signals(ignore_after_stop=True):
            print("ready", flush=True)
            while True:
                time.sleep(0.02)
                check_stop()
    except StopRequested:  # the clean stop writes a resumable state, slowly
        with atomic_file(out / "state.bin") as f:
            f.write(b"half")
            print("stopping", flush=True)
            time.sleep(30)
"""


@pytest.mark.parametrize("second, code, label", [(signal.SIGINT, 130, "SIGINT (Ctrl-C)"), (signal.SIGTERM, 143, "SIGTERM")])
def test_a_second_signal_during_a_slow_clean_stop_ends_within_2_s(tmp_path, second, code, label):
    """The first Ctrl-C begins a clean stop that takes 30 s (the signals are ignored on the way out, as the
    commands do); the second one ends it within 2 s: its own exit status, one line, and the state file that
    was being written is neither there nor left as a temp file."""
    proc = _start(tmp_path, SLOW_CLEAN_STOP)
    rc, took, lines = _stop_twice(proc, signal.SIGINT, second, ready_again="stopping")
    assert rc == code and took < LIMIT_S, (rc, took, lines)
    assert len(lines) == 1 and lines[0].startswith(f"error: stopped by a second {label}; ended at once"), lines
    assert f"{tmp_path / 'state.bin'}: not written" in lines[0], lines
    assert sorted(p.name for p in tmp_path.iterdir()) == [], "a temp file or a half-written state was left"


def test_a_second_signal_during_a_native_call_ends_within_2_s(tmp_path):
    """Inside one long native call Python runs no signal handler: the first Ctrl-C is not acted on (the
    program would stop at its next stop point, minutes later); the second one ends it within 2 s, its line
    ending with the command's advice (lit3d-train: how to resume)."""
    proc = _start(tmp_path, """
        with forced_exit.watching(), on_signals(), forced_exit.advice("resume with ckpt_path=last"):
            print("ready", flush=True)
            native_call()
            check_stop()
    """)
    rc, took, lines = _stop_twice(proc, signal.SIGINT, signal.SIGINT)
    assert rc == 130 and took < LIMIT_S, (rc, took, lines)
    assert lines == ["error: stopped by a second SIGINT (Ctrl-C); ended at once, without the clean stop: nothing was "
                     "half-written; resume with ckpt_path=last"], lines


@pytest.mark.parametrize("stage", ["staging", "committed"])
def test_a_forced_exit_leaves_a_file_set_whole_or_absent(tmp_path, stage):
    """lit3d-reconstruct's sets (lit3d.utils.io.write_file_set) stopped twice inside a native call: one still
    being staged is removed (the earlier set stays), one committed is finished; never a mix, no staging folder."""
    proc = _start(tmp_path, f"""
        import lit3d.utils.io as io
        (out / "a.obj").write_bytes(b"old")
        (out / "a.json").write_bytes(b"old")

        def stall(*args):  # no handler here but Python's: "ready" only once inside the native call
            ready_inside("native_call")
            native_call()

        if "{stage}" == "committed":  # the journal is written: the renames come next
            io.kill_point = lambda point: stall() if point == "file-set:committed" else None
        else:  # the files are staged, the journal not yet written
            io.atomic_write_bytes = stall
        with forced_exit.watching():
            io.write_file_set(out, {{"a.obj": b"new", "a.json": b"new"}})
    """)
    rc, took, lines = _stop_twice(proc, signal.SIGINT, signal.SIGINT)
    assert rc == 130 and took < LIMIT_S, (rc, took, lines)
    want = "new" if stage == "committed" else "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.json", "a.obj"], "a staging folder was left"
    assert {p.read_text() for p in tmp_path.iterdir()} == {want}, "a mix of two sets"
    assert len(lines) == 1 and ("was finished" if stage == "committed" else "was not written") in lines[0], lines


def test_the_first_signal_inside_a_native_step_ends_within_2_s_and_cleans_up(tmp_path):
    """A native step (the Anny cache build) is not worth waiting for: the first SIGTERM ends the process
    within 2 s, after the step's clean-up removed what it was writing."""
    proc = _start(tmp_path, """
        part = out / "cache" / "part.safetensors"
        part.parent.mkdir()
        part.write_bytes(b"12345")  # what the step has written so far

        def cleanup():
            part.unlink()
            return f"removed the part-written {part.name}"

        with forced_exit.watching("tool: "), forced_exit.native_step("while building a cache", cleanup):
            print("ready", flush=True)
            native_call()
    """)
    _wait_for(proc, "ready")
    proc.send_signal(signal.SIGTERM)
    rc, took, lines = _ends_within(proc)
    assert rc == 143 and took < LIMIT_S, (rc, took, lines)
    assert lines == ["tool: error: stopped by SIGTERM while building a cache; ended at once, without the clean "
                     "stop: removed the part-written part.safetensors; files finished before are kept, and the next "
                     "run clears what an interrupted one leaves"], lines
    assert not (tmp_path / "cache" / "part.safetensors").exists()


def test_a_command_that_said_its_stop_line_ends_with_its_status_and_no_second_line(tmp_path):
    """A command that has said its stop line (exit 143) and then hangs on its way out: a second signal ends
    it with that status and adds no line."""
    proc = _start(tmp_path, """
        with forced_exit.watching():
            try:
                print("ready", flush=True)
                time.sleep(30)
            except KeyboardInterrupt:
                signal.signal(signal.SIGINT, forced_exit.ignore)  # on its way out, as the commands are
                forced_exit.said(143)
                print("error: stopped by SIGINT (Ctrl-C); the same command again resumes", file=sys.stderr, flush=True)
                print("said", flush=True)
                time.sleep(30)  # an exit that hangs
    """)
    rc, took, lines = _stop_twice(proc, signal.SIGINT, signal.SIGINT, ready_again="said")
    assert rc == 143 and took < LIMIT_S, (rc, took, lines)
    assert lines == ["error: stopped by SIGINT (Ctrl-C); the same command again resumes"], lines


def test_a_forked_childs_ctrl_c_is_not_the_parents_second(tmp_path):
    """Ctrl-C in a terminal reaches the whole process group, forked workers included: each worker's signal
    is its own (before the at-fork hook it reached the parent's watcher, a second signal at the first
    Ctrl-C). The parent makes its clean stop, which takes longer than the forced exit's grace."""
    proc = _start(tmp_path, """
        with forced_exit.watching():
            with on_signals(ignore_after_stop=True):
                pid = os.fork()
                if pid == 0:  # a worker: its own Ctrl-C ends it
                    signal.signal(signal.SIGINT, signal.default_int_handler)
                    try:
                        time.sleep(30)
                    finally:
                        os._exit(0)
                print("ready", flush=True)
                try:
                    while True:
                        time.sleep(0.02)
                        check_stop()
                except StopRequested:
                    os.waitpid(pid, 0)
                    time.sleep(1.5)  # the clean stop
                    print("clean stop", file=sys.stderr, flush=True)
                    sys.exit(143)
    """, start_new_session=True)
    _wait_for(proc, "ready")
    time.sleep(0.2)
    os.killpg(proc.pid, signal.SIGINT)
    rc, took, lines = _ends_within(proc, limit=30)
    assert rc == 143 and lines == ["clean stop"], (rc, lines)


# ----------------------------------------------------------------------------- the Anny cache's first build
def _safetensors(path: Path, data_bytes: int = 16, cut: int = 0) -> Path:
    """A small safetensors file (one tensor of ``data_bytes`` bytes), ``cut`` bytes short."""
    header = json.dumps({"t": {"dtype": "U8", "shape": [data_bytes], "data_offsets": [0, data_bytes]}}).encode()
    blob = struct.pack("<Q", len(header)) + header + bytes(data_bytes)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(blob[:len(blob) - cut])
    return path


@pytest.fixture
def anny_cache_in(tmp_path, monkeypatch):
    """anny's cache folder moved to an empty temp folder (the real one is never touched)."""
    pytest.importorskip("anny")
    import anny.paths

    monkeypatch.setattr(anny.paths, "_ANNY_CACHE_DIR", [tmp_path / "anny"])
    return tmp_path / "anny"


def test_the_model_file_is_the_one_anny_looks_for(anny_cache_in, monkeypatch):
    """:func:`model_file` names the file anny.Anny() checks first (caught at anny's own exists() check,
    before anything is built)."""
    import anny
    from anny.models import model_data

    from lit3d.body_model.anny_cache import model_file

    class Looked(Exception):
        pass

    class Probe(type(Path())):
        def exists(self, *args, **kwargs):
            raise Looked(self)

    monkeypatch.setattr(model_data, "Path", Probe)
    with pytest.raises(Looked) as looked:
        anny.Anny()
    assert Path(looked.value.args[0]) == model_file() and model_file().is_relative_to(anny_cache_in)


def test_the_first_build_speaks_and_a_built_cache_is_silent(anny_cache_in):
    from lit3d.body_model.anny_cache import first_build, model_file

    lines = []
    with first_build(lines.append, every_s=0.25):
        time.sleep(0.7)
    assert lines[0] == ("building the Anny body model's cache in " + str(anny_cache_in) + " (about 790 MB; about 2 min "
                        "30 s on 2 idle cores, once; Ctrl-C stops it, and the next start builds it again)"), lines
    assert len(lines) >= 2 and lines[1].startswith("building the Anny body model's cache: 0 s, about 2 min 30 s left")
    _safetensors(model_file())
    lines.clear()
    with first_build(lines.append, every_s=0.1):
        time.sleep(0.3)
    assert lines == [], "spoke with the cache there"


def test_a_stopped_build_removes_its_part_written_file_and_a_stale_one_is_rebuilt(anny_cache_in):
    from lit3d.body_model.anny_cache import first_build, model_file

    folder = model_file().parent
    whole = _safetensors(folder / "load_data_0.safetensors")
    lines = []
    with pytest.raises(KeyboardInterrupt), first_build(lines.append):
        part = _safetensors(folder / "build_model_data_0.safetensors", cut=5)  # anny writing, stopped
        raise KeyboardInterrupt
    assert whole.is_file() and not part.exists()
    assert "about 255 MB; about 18 s" in lines[0], lines  # what load_data leaves to build

    stale = _safetensors(model_file(), cut=3)  # a killed build's truncated file: anny would fail to read it
    os.utime(stale, (time.time() - 120, time.time() - 120))
    fresh = _safetensors(folder / "build_model_data_1.safetensors", cut=3)  # another process writing it now
    lines.clear()
    with first_build(lines.append):
        pass
    assert not stale.exists() and fresh.exists() and whole.exists()
    assert lines[0] == f"removed {stale}: a truncated file of the Anny cache that an interrupted first start left " \
                       "(anny cannot read it); it is built again", lines


def test_body_model_says_the_first_build_on_stderr(anny_cache_in, monkeypatch, capfd):
    """BodyModel.model's build runs with stderr open (warp's start-up notes are silenced before it): its
    lines reach the console."""
    import anny

    import lit3d.body_model.anny_cache as anny_cache
    from lit3d.body_model.bodies import BodyModel

    class SlowAnny:
        def __init__(self):
            time.sleep(0.5)

        def to(self, dtype):
            return self

    target = anny_cache.model_file()  # named from anny.Anny's defaults, which SlowAnny has not
    monkeypatch.setattr(anny_cache, "model_file", lambda: target)
    monkeypatch.setattr(anny, "Anny", SlowAnny)
    monkeypatch.setattr(progress_module, "EVERY_S", 0.2)
    # file descriptor 2 itself, as a print to the real stderr reaches it (pytest replaces sys.stderr)
    monkeypatch.setattr(anny_cache, "say_or_log", lambda line: os.write(2, f"{line}\n".encode()))
    assert isinstance(BodyModel().model, SlowAnny)
    err = capfd.readouterr().err
    assert "building the Anny body model's cache in " in err and "building the Anny body model's cache: 0 s" in err, err


@pytest.mark.slow
def test_ctrl_c_during_a_real_first_anny_build_ends_within_2_s(tmp_path):
    """lit3d-reconstruct --body with an empty ANNY_CACHE_DIR (a real first build, minutes): the start line and a
    heartbeat on stderr, then one Ctrl-C ends it within 2 s with one line, exit 130, no part-written cache
    file and nothing in --out."""
    from lit3d.body_model.anny_cache import is_whole
    from tests.helpers.body import INTR, H, W, save_depth_mm

    import trimesh

    from lit3d.reconstruct.synthetic import render_depth_pinhole

    box = trimesh.creation.box((0.6, 1.0, 0.5))
    box.apply_translation((0.0, 0.2, 2.8))
    save_depth_mm(tmp_path / "box.png", render_depth_pinhole(box, INTR, W, H))
    env = {**os.environ, "ANNY_CACHE_DIR": str(tmp_path / "anny"), "PYTHONPATH": str(REPO)}
    proc = subprocess.Popen([sys.executable, "-c", "import sys; from lit3d.cli.reconstruct import main; sys.exit(main())",
                             str(tmp_path / "box.png"), "--body", "--out", str(tmp_path / "out")],
                            cwd=REPO, env=env, text=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    seen = []
    for line in proc.stderr:
        seen.append(line.rstrip())
        if "building the Anny body model's cache: " in line:  # the first heartbeat, about 10 s in
            break
    assert any("building the Anny body model's cache in " in ln for ln in seen), seen
    proc.send_signal(signal.SIGINT)
    rc, took, lines = _ends_within(proc)
    print(f"exit {rc} {took:.2f} s after SIGINT, {len(seen)} lines before it: {lines}")
    assert rc == 130 and took < LIMIT_S, (rc, took, seen, lines)
    # the watcher's line, or the command's own stop line where Python got to run its handler first (the build
    # was in Python code, not inside one long native call)
    assert len(lines) == 1 and lines[0].startswith(("lit3d-reconstruct: error: stopped by SIGINT (Ctrl-C) while building "
                                                    "the Anny body model's cache; ended at once",
                                                    "lit3d-reconstruct: interrupted at image 1 of 1: nothing new")), lines
    assert all(is_whole(p) for p in (tmp_path / "anny").rglob("*.safetensors"))
    assert not (tmp_path / "out").exists()
