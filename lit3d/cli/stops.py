"""Ctrl-C (SIGINT) and SIGTERM outside training: while data is prepared, during ``lit3d-eval`` and in the
test after training.

(Training has its own path, :func:`lit3d.cli.train.fit`: ``last.ckpt`` saved, a resume line.)
Both blocks below handle the two signals with :func:`lit3d.utils.stops.on_signals`: the first is
acted on at the next stop point (the next data item, the end of the current batch, the next step
of an evaluation), a second one at once; either way the command ends with
:class:`~lit3d.cli.common.Interrupted`: exit 143 (as a stopped training) and one line on stderr,

- :func:`preparing` (``lit3d-data``; ``lit3d-train`` before it trains):
  ``error: <data_dir>: stopped by SIGINT (Ctrl-C) while preparing data (12 of 60 items done); the
  same command again resumes``: the finished items are kept, the rerun makes the missing ones;
- :func:`evaluating` (``lit3d-eval``): ``error: <run dir>: stopped by SIGINT (Ctrl-C) during
  evaluation; nothing was written (...)``; the outputs are written as one set at the end
  (:mod:`lit3d.cli.evaluation`), so a stopped evaluation leaves none of them;
- :func:`testing_after_fit` (``lit3d-train``'s test after fitting): ``error: <run dir>: stopped by ...
  while testing after training; the training is complete and its checkpoints are kept; ...: test with
  lit3d-eval ckpt_path=<best>``.
"""
from __future__ import annotations

import contextlib
from collections.abc import Iterator
from pathlib import Path

from lit3d.runtime.errors import Interrupted
from lit3d.utils import forced_exit
from lit3d.utils.stops import StopRequested, check_stop, on_signals, pending


def preparation_stopped(stop: StopRequested, data_dir: str | Path) -> str:
    """The stop line of an interrupted data preparation (the folder :class:`StopRequested` names,
    else ``data_dir``), with the count of finished items where it is known."""
    counts = ""
    if stop.done is not None:
        counts = f" ({stop.done} of {stop.total} items done)" if stop.total is not None else f" ({stop.done} items done)"
    return (f"{stop.where or data_dir}: stopped by {stop.label} while preparing data{counts}; "
            "the same command again resumes")


@contextlib.contextmanager
def preparing(data_dir: str | Path) -> Iterator[None]:
    """Prepare data inside the block; Ctrl-C or SIGTERM stops it at the next item (module doc); after a
    stop the command ignores further signals while it exits. A signal after the last item's stop point
    stops the command at the end of the block (it was forgotten there, and the command went on to train)."""
    try:
        with on_signals(ignore_after_stop=True), forced_exit.advice(
                f"the finished items in {data_dir} are kept; the same command again resumes"):
            yield
            check_stop()
    except StopRequested as stop:
        raise Interrupted(preparation_stopped(stop, data_dir)) from None


@contextlib.contextmanager
def _stop_points() -> Iterator[None]:
    """Signals as stop requests inside the block, Lightning's SIGTERM flag included; ignored after a stop."""
    from lightning.pytorch.utilities.exceptions import SIGTERMException

    with on_signals(ignore_after_stop=True):
        try:
            yield
        except SIGTERMException:  # Lightning's own SIGTERM flag, set by its handler beside ours
            raise StopRequested(pending() or "SIGTERM") from None


@contextlib.contextmanager
def evaluating(run_dir: str | Path) -> Iterator[None]:
    """Evaluate inside the block; Ctrl-C or SIGTERM stops it at the next stop point (module doc):
    a stop while the data is prepared says so (:func:`preparing`'s line); after a stop the command
    ignores further signals while it exits."""
    try:
        with _stop_points():
            yield
    except StopRequested as stop:
        if stop.where is not None:
            raise Interrupted(preparation_stopped(stop, stop.where)) from None
        raise Interrupted(f"{run_dir}: stopped by {stop.label} during evaluation; nothing was written (metrics.json, "
                          "results.md, config.yaml and the figures are written together at the end); the same "
                          "command again evaluates") from None


@contextlib.contextmanager
def testing_after_fit(run_dir: str | Path, ckpt: str) -> Iterator[None]:
    """``lit3d-train``'s test of ``ckpt`` after fitting, inside the block: Ctrl-C or SIGTERM stops it at the
    next stop point with one line (exit 143) saying that the training is complete and its checkpoints
    kept, that no test output was written, and the ``lit3d-eval`` command that tests it."""
    try:
        with _stop_points():
            yield
    except StopRequested as stop:
        raise Interrupted(f"{run_dir}: stopped by {stop.label} while testing after training; the training is "
                          "complete and its checkpoints are kept; no test results were written (metrics.json, "
                          f"results.md, figures): test with lit3d-eval ckpt_path={ckpt} hydra.run.dir={run_dir}/eval"
                          ) from None
