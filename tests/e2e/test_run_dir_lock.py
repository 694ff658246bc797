"""One process per run dir (``lit3d.cli.rundir``), checked with real processes.

- a second ``lit3d-train`` into a busy run dir is refused with one line naming the holder, and
  writes nothing there (``.hydra/config.yaml`` stays the first run's);
- ``wait_for_run_dir=true`` waits for the holder instead; a lock left by a killed process
  (SIGKILL) is no lock at all;
- timestamped run dirs never collide: runs started while ``<time>`` exists get ``<time>_2``,
  ``<time>_3`` ... and never write into another run's dir.
"""
from __future__ import annotations

import subprocess
import sys
import time
from datetime import datetime, timedelta
from pathlib import Path

from tests.helpers.runs import BIN, CANONICAL, REPO, child_env, start_script

# a few tiny completion items: lit3d-data runs in seconds
TINY_DATA = ["experiment=completion_demo", "data.sizes={train:2,val:1,test_same:1,test_cross:1,test_unseen:1}",
             "data.prepare.progress=false"]


def _run(args: list[str], timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run([str(BIN / args[0]), *args[1:]], cwd=REPO, env=child_env(), capture_output=True, text=True,
                          timeout=timeout)


def _errors(stderr: str) -> list[str]:
    return [ln for ln in stderr.splitlines() if ln.startswith("error:")]


def _wait_for(cond, proc: subprocess.Popen, log: Path, timeout: float = 120) -> None:
    t0 = time.monotonic()
    while not cond():
        assert proc.poll() is None, log.with_suffix(".err").read_text()[-3000:]
        assert time.monotonic() - t0 < timeout, "timed out"
        time.sleep(0.1)


def _holder(run: Path) -> subprocess.Popen:
    """A process that holds ``run``'s lock (it prints ``held`` once it does) until its stdin closes."""
    code = ("import sys; from lit3d.cli.rundir import lock_run_dir; lock_run_dir(sys.argv[1]); "
            "print('held', flush=True); sys.stdin.read()")
    proc = subprocess.Popen([sys.executable, "-c", code, str(run)], cwd=REPO, env=child_env(),
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "held"
    return proc


def test_second_training_into_a_busy_run_dir_is_refused(tmp_path):
    run = tmp_path / "run"
    common = [*CANONICAL, "logger=none", f"paths.data_dir={tmp_path}/data", f"hydra.run.dir={run}"]
    first = start_script(["lit3d-train", *common, "trainer.max_epochs=500", "task.optimizer.lr=0.001"], tmp_path / "first")
    try:
        # Hydra writes config.yaml, hydra.yaml, then overrides.yaml (not atomically): wait until all are written
        written = [run / ".hydra" / n for n in ("config.yaml", "overrides.yaml")]
        _wait_for(lambda: all(f.is_file() and f.stat().st_size > 0 for f in written), first, tmp_path / "first")
        hydra_cfg = (run / ".hydra" / "config.yaml").read_bytes()
        res = _run(["lit3d-train", *common, "trainer.max_epochs=1", "task.optimizer.lr=0.05"])
        assert res.returncode == 2, res.stderr[-3000:]
        assert "Traceback" not in res.stderr
        assert _errors(res.stderr) == [ln for ln in res.stderr.splitlines() if ln.strip()][-1:]
        line = _errors(res.stderr)[0]
        assert line.startswith(f"error: {run}: run dir in use by pid {first.pid} on "), line
        assert " since 20" in line and "wait_for_run_dir=true" in line
        assert (run / ".hydra" / "config.yaml").read_bytes() == hydra_cfg  # the second run wrote nothing there
        assert first.poll() is None  # the first run goes on
    finally:
        first.kill()
        first.wait(timeout=60)


def test_wait_for_run_dir_waits_and_a_killed_holder_leaves_no_lock(tmp_path):
    from lit3d.cli.rundir import LOCK_FILE

    run = tmp_path / "run"
    args = ["lit3d-data", *TINY_DATA, f"paths.data_dir={tmp_path}/data", f"hydra.run.dir={run}"]
    holder = _holder(run)
    waiting = start_script([*args, "wait_for_run_dir=true"], tmp_path / "waiting")
    err = tmp_path / "waiting.err"
    _wait_for(lambda: "waiting for it" in err.read_text(), waiting, tmp_path / "waiting")
    assert f"{run}: run dir in use by pid {holder.pid} on " in err.read_text()
    time.sleep(1)
    assert waiting.poll() is None  # still waiting
    holder.stdin.close()  # the holder exits
    assert holder.wait(timeout=30) == 0
    assert waiting.wait(timeout=180) == 0, err.read_text()[-3000:]
    # a holder killed with SIGKILL: the system released its lock; the next run needs no waiting
    holder = _holder(run)
    holder.kill()
    holder.wait(timeout=30)
    res = _run(args)
    assert res.returncode == 0, res.stderr[-3000:]
    assert "in use" not in res.stderr
    assert (run / LOCK_FILE).read_text() == ""  # released at exit: no holder named any more


def test_timestamped_run_dirs_never_collide(tmp_path):
    runs = tmp_path / "logs" / "completion" / "runs"
    now = datetime.now()
    taken = [runs / (now + timedelta(seconds=s)).strftime("%Y-%m-%d_%H-%M-%S") for s in range(-2, 120)]
    for d in taken:  # every second of the next two minutes already has a run
        d.mkdir(parents=True)
        (d / "other_run.txt").write_text("x")
    args = ["lit3d-data", *TINY_DATA, f"paths.data_dir={tmp_path}/data", f"paths.log_dir={tmp_path}/logs"]
    procs = [start_script(args, tmp_path / f"p{i}") for i in range(2)]  # two runs started at the same time
    for i, p in enumerate(procs):
        assert p.wait(timeout=180) == 0, (tmp_path / f"p{i}.err").read_text()[-3000:]
    for d in taken:
        assert sorted(q.name for q in d.iterdir()) == ["other_run.txt"], f"a run wrote into {d}"
    new = sorted(set(runs.iterdir()) - set(taken))
    assert len(new) == 2, new
    for d in new:
        stamp, _, k = d.name.rpartition("_")
        assert runs / stamp in taken and int(k) >= 2, d.name
        assert (d / ".hydra" / "config.yaml").is_file()


def test_a_run_that_waited_never_replaces_the_finished_run(tmp_path):
    """``wait_for_run_dir=true`` once waited, then trained afresh in the same dir, replacing the finished
    run's metrics.json, config.yaml, results.md, curves.png and last.ckpt without a word. Now it stops
    with one line naming the dir, its results and how to continue that run, and writes nothing."""
    run = tmp_path / "run"
    holder = _holder(run)
    args = ["lit3d-train", *TINY_DATA, "logger=none", f"paths.data_dir={tmp_path}/data", f"hydra.run.dir={run}",
            "wait_for_run_dir=true"]
    waiting = start_script(args, tmp_path / "waiting")
    err = tmp_path / "waiting.err"
    _wait_for(lambda: "waiting for it" in err.read_text(), waiting, tmp_path / "waiting")
    # the run it waits for finishes: its results are in the dir when it lets go
    (run / "checkpoints").mkdir()
    results = {run / "metrics.json": b'{"test/iou": 0.5}\n', run / "config.yaml": b"seed: 42\n",
               run / "results.md": b"# results\n", run / "curves.png": b"png", run / "checkpoints" / "last.ckpt": b"ckpt"}
    for path, data in results.items():
        path.write_bytes(data)
    holder.stdin.close()
    assert holder.wait(timeout=30) == 0
    assert waiting.wait(timeout=180) == 2, err.read_text()[-3000:]
    text = err.read_text()
    assert "Traceback" not in text
    assert _errors(text) == [ln for ln in text.splitlines() if ln.strip()][-1:]
    assert _errors(text)[0] == (
        f"error: {run}: the run this one waited for left its results here (metrics.json, results.md, config.yaml, "
        f"curves.png, checkpoints/last.ckpt); a run started with wait_for_run_dir=true never replaces them: "
        f"continue it with the same overrides plus hydra.run.dir={run} ckpt_path=last, or choose another "
        "hydra.run.dir")
    assert {p: p.read_bytes() for p in results} == results
    assert not (run / ".hydra").exists()  # Hydra wrote nothing there


def test_what_a_run_that_waited_may_do(tmp_path):
    """The rule of :func:`lit3d.cli.rundir.check_waited`: a training that continues the run (``ckpt_path=last``
    or one of its checkpoints) and the commands that write no results go on; a fresh one and an evaluation stop."""
    import pytest

    from lit3d.cli.rundir import check_waited
    from lit3d.utils.io import OutputError

    run = tmp_path / "run"
    check_waited(run, "train")  # no run dir yet: nothing to replace
    (run / "checkpoints").mkdir(parents=True)
    check_waited(run, "train")  # an empty dir (a lit3d-data run's, Hydra's folder only): nothing to replace
    (run / "checkpoints" / "epoch=1.ckpt").write_bytes(b"x")
    for command, ckpt in (("train", "last"), ("train", run / "checkpoints" / "epoch=1.ckpt"), ("data", None),
                          ("summary", None)):
        check_waited(run, command, ckpt)
    for command, ckpt in (("train", None), ("train", tmp_path / "elsewhere.ckpt"), ("eval", "last")):
        with pytest.raises(OutputError, match=r"left its results here \(checkpoints/epoch=1.ckpt\).*: choose another"):
            check_waited(run, command, ckpt)


def test_an_optuna_search_without_dash_m_claims_no_run_dir(tmp_path):
    """``lit3d-train hparams_search=...`` sweeps (``hydra.mode: MULTIRUN``): its jobs run in the sweep
    dir, so no ``runs/<time>`` dir with a lock file is made for it; a plain run still claims its dir."""
    from lit3d.runtime.compose import compose_config
    from lit3d.cli.rundir import claim_run_dir

    common = ["experiment=completion_demo", f"paths.log_dir={tmp_path}/logs"]
    cfg = compose_config("train", ["hparams_search=completion_optuna", *common], return_hydra_config=True)
    args, lock = claim_run_dir(cfg, ["hparams_search=completion_optuna", *common])
    with lock:
        assert args == ["hparams_search=completion_optuna", *common]
        assert not (tmp_path / "logs").exists()
    cfg = compose_config("train", common, return_hydra_config=True)
    args, lock = claim_run_dir(cfg, common)
    with lock:
        runs = list((tmp_path / "logs" / "completion" / "runs").iterdir())
        assert len(runs) == 1 and (runs[0] / ".lit3d.lock").exists() and args[-1] == f"hydra.run.dir={runs[0]}"
