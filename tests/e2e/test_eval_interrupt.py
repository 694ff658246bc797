"""Ctrl-C or SIGTERM during ``lit3d-eval`` ends with one line, and a run dir never
holds half an evaluation.

Before: Ctrl-C in the test loop ended with Lightning's "Detected KeyboardInterrupt" and exit 1 (a
traceback elsewhere), SIGTERM killed the process, and ``metrics.json`` and ``results.md`` were written
before ``config.yaml`` and the figures, so a stopped evaluation looked finished. Now the stop is acted
on after the current batch or step (exit 143, as a stopped training, and one line
``error: <run dir>: stopped by SIGINT (Ctrl-C) during evaluation; nothing was written ...``), and the
outputs are staged and moved into the run dir as one set, ``metrics.json`` last
(:mod:`lit3d.cli.evaluation`): a stop writes none of them and an earlier evaluation's files stay.

Real ``lit3d-eval`` processes on an untrained checkpoint of tiny completion nets and data prepared
before (so the stop lands in the evaluation, not in the preparation).
"""
from __future__ import annotations

import json
import signal
from pathlib import Path

import pytest
from tests.helpers.completion import TINY_SIZES as SIZES, prepared_tiny_checkpoint
from tests.helpers.runs import TINY_NETS, start_script
from tests.helpers.signals import signal_when, stop_line

from lit3d.cli import evaluation

OUTPUTS = ("metrics.json", "results.md", "config.yaml")


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory) -> Path:
    """An untrained tiny completion checkpoint whose data config (prepared here) is the one evaluated."""
    return prepared_tiny_checkpoint(tmp_path_factory.mktemp("eval_interrupt"))


def _expected(run: Path, what: str) -> str:
    return (f"error: {run}: stopped by {what} during evaluation; nothing was written (metrics.json, results.md, "
            "config.yaml and the figures are written together at the end); the same command again evaluates")


def _results(run: Path) -> list[str]:
    """What an evaluation writes into the run dir (and its staging folders)."""
    return sorted(p.name for p in run.iterdir() if p.name not in (".hydra", ".lit3d.lock", "evaluate.log"))


def test_ctrl_c_while_testing_exits_with_one_line_and_writes_nothing(tmp_path, checkpoint):
    run, log = tmp_path / "run", tmp_path / "eval"
    proc = start_script(["lit3d-eval", f"ckpt_path={checkpoint}", f"hydra.run.dir={run}"], log)
    # the Trainer is built (its first log line): the handlers are in place, validation comes next
    def started():
        return "GPU available" in ((run / "evaluate.log").read_text() if (run / "evaluate.log").is_file() else "")

    rc = signal_when(proc, started, log, [signal.SIGINT])
    assert stop_line(log, rc) == _expected(run, "SIGINT (Ctrl-C)")
    assert _results(run) == [], "a stopped evaluation left files in its run dir"


def test_sigterm_while_the_outputs_are_written_keeps_the_earlier_evaluation(tmp_path, checkpoint):
    """SIGTERM while the figures are made: the earlier evaluation in that run dir stays whole; none of
    this one's files (metrics.json, results.md, config.yaml, figures) is mixed in."""
    run, log = tmp_path / "run", tmp_path / "eval"
    run.mkdir()
    earlier = {"metrics.json": json.dumps({"earlier": True}) + "\n", "results.md": "earlier\n",
               "config.yaml": "earlier: true\n"}
    for name, text in earlier.items():
        (run / name).write_text(text)
    proc = start_script(["lit3d-eval", f"ckpt_path={checkpoint}", f"hydra.run.dir={run}"], log)

    def writing() -> bool:  # this evaluation's files are being written (staged; before: into the run dir)
        return any(p.name.startswith(".evaluation.") for p in run.iterdir()) or \
            (run / "metrics.json").read_text() != earlier["metrics.json"]

    rc = signal_when(proc, writing, log, [signal.SIGTERM])
    assert stop_line(log, rc) == _expected(run, "SIGTERM")
    assert {name: (run / name).read_text() for name in earlier} == earlier
    assert _results(run) == sorted(earlier), "files of the stopped evaluation were left beside the earlier ones"


# ----------------------------------------------------------------------------- the staging, in-process
def test_staged_outputs_are_moved_as_one_set_metrics_last(tmp_path, monkeypatch):
    out = tmp_path / "run"
    out.mkdir()
    (out / "metrics.json").write_text("earlier\n")
    with pytest.raises(RuntimeError), evaluation.staged_outputs(out) as stage:
        (stage / "metrics.json").write_text("new\n")
        (stage / "results.md").write_text("new\n")
        raise RuntimeError("a figure writer failed")
    assert sorted(p.name for p in out.iterdir()) == ["metrics.json"] and (out / "metrics.json").read_text() == "earlier\n"

    moved, real = [], evaluation.write_file_set
    monkeypatch.setattr(evaluation, "write_file_set", lambda d, files, *a: moved.append(list(files)) or real(d, files, *a))
    with evaluation.staged_outputs(out) as stage:
        for name in ("config.yaml", "metrics.json", "results.md", "z.png"):
            (stage / name).write_text("new\n")
    assert moved == [["config.yaml", "results.md", "z.png", "metrics.json"]]
    assert sorted(p.name for p in out.iterdir()) == ["config.yaml", "metrics.json", "results.md", "z.png"]
    assert all((out / n).read_text() == "new\n" for n in moved[0])


def test_ctrl_c_while_testing_after_training_keeps_the_training_and_says_how_to_test(tmp_path):
    """lit3d-train's test after fitting: before, Ctrl-C there ended with Lightning's KeyboardInterrupt and exit 1;
    now one line (exit 143) says the training is complete, names the checkpoint and the lit3d-eval command,
    and no test output is written."""
    run, log = tmp_path / "run", tmp_path / "train"
    proc = start_script(["lit3d-train", "experiment=completion_demo", *TINY_NETS, SIZES, "data.batch_size=2",
                   "data.prepare.progress=false", f"paths.data_dir={tmp_path}/data", "trainer.max_epochs=1", "logger=none",
                   "callbacks.progress_bar=null", f"hydra.run.dir={run}"], log)
    def testing():
        return "testing " in ((run / "train.log").read_text() if (run / "train.log").is_file() else "")

    rc = signal_when(proc, testing, log, [signal.SIGINT])
    line = stop_line(log, rc)
    assert line.startswith(f"error: {run}: stopped by SIGINT (Ctrl-C) while testing after training; the training is "
                           "complete and its checkpoints are kept; no test results were written"), line
    ckpt = Path(line.split("ckpt_path=")[1].split()[0])
    assert ckpt.is_file() and ckpt.parent == run / "checkpoints"
    assert not (run / "metrics.json").exists() and not (run / "results.md").exists()
