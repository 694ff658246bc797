"""The evaluation of ``lit3d-eval`` and of ``lit3d-train`` after fitting: test, the task room's
protocol, and its files written into the run dir as one set (``lit3d-eval split=val``: :func:`run_validation`).

:func:`run_evaluation` writes ``metrics.json``, ``results.md``, the artefacts, the figures (and the
caller's own files, ``lit3d-eval``'s ``config.yaml``) into a hidden staging folder of the run dir
(``.evaluation.<pid>-<host>.<random>.tmp/``), and only when every one is complete moves them into the run dir
with :func:`lit3d.utils.io.write_file_set`, ``metrics.json`` last. A run stopped before (Ctrl-C,
SIGTERM, an error, a full disk) writes none of them, and the files of an earlier evaluation in the
same run dir stay as they were: a folder with a ``metrics.json`` holds a whole evaluation. A run
killed during the renames leaves the set's journal; the next evaluation into that run dir finishes
the renames first (:func:`lit3d.utils.io.repair_sets`).
"""
from __future__ import annotations

import contextlib
import logging
import shutil
import tempfile
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path

from lit3d.runtime.registry import evaluator_module
from lit3d.utils.io import STAGE_PREFIX, TMP_SUFFIX, atomic_write_text, repair_sets, write_file_set, write_json
from lit3d.utils.kill_points import kill_point
from lit3d.utils.stops import check_stop, shielded
from lit3d.utils.temp_names import temp_prefix

log = logging.getLogger("lit3d")

METRICS = "metrics.json"  # written last: its presence marks a finished evaluation


def scalar_metrics(metrics: dict) -> dict[str, float]:
    """The one-number entries of Lightning's ``callback_metrics`` as floats."""
    import torch

    return {k: float(v) for k, v in metrics.items() if torch.as_tensor(v).numel() == 1}


@contextlib.contextmanager
def staged_outputs(out_dir: Path, last: str = METRICS) -> Iterator[Path]:
    """A staging folder in ``out_dir`` for the block to write its files into (flat, no subfolders);
    after the block they are moved into ``out_dir`` as one set, ``last`` last (see the module doc).
    An error or a stop in the block writes nothing; an OSError names the file in ``out_dir``, not in
    the staging folder. The staging folder is removed in every case."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    for note in repair_sets(out_dir):  # a set an earlier, killed evaluation left half renamed
        log.info(note)
    stage = Path(tempfile.mkdtemp(dir=out_dir, prefix=temp_prefix(STAGE_PREFIX.strip(".")), suffix=TMP_SUFFIX))
    try:
        try:
            yield stage
        except OSError as exc:
            name = Path(exc.filename or "")
            if exc.errno is None or stage not in name.parents:
                raise
            raise OSError(exc.errno, exc.strerror, str(out_dir / name.relative_to(stage))) from exc
        check_stop()  # a Ctrl-C while the files were written: none is moved
        names = sorted((p.name for p in stage.iterdir() if p.is_file()), key=lambda n: (n == last, n))
        kill_point("evaluation:staged")
        with shielded():  # the renames are finished together (a second Ctrl-C waits for them)
            write_file_set(out_dir, {n: (stage / n).read_bytes() for n in names})
    finally:
        shutil.rmtree(stage, ignore_errors=True)


def run_evaluation(trainer, task, datamodule, task_name: str, out_dir: Path, *, ckpt_path: str | None = None,
                   validate: bool = False, n_figures: int = 0, extra: dict | Callable[[], dict] | None = None,
                   files: dict[str, str] | None = None, settings: Mapping | None = None,
                   measured: Mapping[str, float] | None = None) -> dict[str, float]:
    """Test ``task`` (after validating it when ``validate``: the completion threshold is chosen there),
    run the task room's evaluator on the result with the evaluation ``settings`` (the config's
    ``evaluation`` node, :mod:`lit3d.runtime.eval_settings`), and on rank 0 write ``metrics.json``, ``results.md``,
    the artefacts and ``n_figures`` figures per split into ``out_dir`` as one set
    (:func:`staged_outputs`). Used by ``lit3d-eval`` and, after fitting, by ``lit3d-train``.
    ``extra``: entries written first into ``metrics.json`` (not returned), or a function returning
    them (called after the test: the data's manifest is known then); ``files``: more files of the
    set (name -> text); ``measured``: ``val/`` numbers of the tested weights already known (``lit3d-train``:
    the monitored value of the best checkpoint, :func:`lit3d.cli.train.tested_validation`), kept in the
    metrics as a validation here would. Between the steps and after every batch (:mod:`lit3d.utils.stops`) a Ctrl-C
    or SIGTERM under :func:`lit3d.utils.stops.on_signals` stops it, before anything is written."""
    evaluator = evaluator_module(task_name)
    settings = dict(settings or {})
    metrics: dict[str, float] = {k: float(v) for k, v in (measured or {}).items() if k.startswith("val/")}
    if validate:
        trainer.validate(task, datamodule=datamodule, ckpt_path=ckpt_path, weights_only=True)
        metrics.update({k: v for k, v in scalar_metrics(trainer.callback_metrics).items() if k.startswith("val/")})
        check_stop()
    evaluator.prepare(task, settings)
    trainer.test(task, datamodule=datamodule, ckpt_path=ckpt_path, weights_only=True)
    metrics.update({k: v for k, v in scalar_metrics(trainer.callback_metrics).items() if k.startswith("test/")})
    check_stop()
    evaluation = evaluator.protocol(task, datamodule, settings)  # on every rank: it may synchronise states
    protocol_metrics = evaluation.metrics
    metrics.update(protocol_metrics)
    check_stop()
    if trainer.is_global_zero:
        for logger in trainer.loggers:  # the module logged its own metrics; these come after the test
            if protocol_metrics:
                logger.log_metrics(protocol_metrics, step=trainer.global_step)
        head = extra() if callable(extra) else dict(extra or {})
        with staged_outputs(out_dir) as stage:
            for name, text in (files or {}).items():
                atomic_write_text(stage / name, text)
            write_json(stage / METRICS, {**head, **metrics})  # first: a figure writer may read it
            evaluator.write_artefacts(evaluation, stage)
            evaluator.write_results(metrics, stage)
            check_stop()
            figures = (evaluator.write_figures(task, datamodule, stage, n=n_figures, evaluation=evaluation)
                       if n_figures > 0 else [])
        log.info("wrote %s, results.md and %d figures", out_dir / METRICS, len(figures))
    return metrics


def run_validation(trainer, task, datamodule, task_name: str, out_dir: Path, *,
                   extra: dict | Callable[[], dict] | None = None, files: dict[str, str] | None = None,
                   settings: Mapping | None = None) -> dict[str, float]:
    """``lit3d-eval split=val``: validate ``task`` only (the task's ``val/`` metrics, e.g. the canonical
    task's ``val/retrieval_nn``: choose settings on validation people, not on the test set), then the task
    room's ``validation_protocol`` (the canonical task's validation predictions, ``heldout.npz``), and on
    rank 0 write ``metrics.json`` (``extra`` first, ``"split": "val"``, the metrics), the artefacts and
    ``files`` into ``out_dir`` as one set (:func:`staged_outputs`); no results.md or figures (those are the
    test's)."""
    evaluator = evaluator_module(task_name)
    trainer.validate(task, datamodule=datamodule, weights_only=True)
    metrics = {k: v for k, v in scalar_metrics(trainer.callback_metrics).items() if k.startswith("val/")}
    check_stop()
    evaluation = evaluator.validation_protocol(trainer, task, datamodule, dict(settings or {}))  # every rank
    check_stop()
    if trainer.is_global_zero:
        head = extra() if callable(extra) else dict(extra or {})
        with staged_outputs(out_dir) as stage:
            for name, text in (files or {}).items():
                atomic_write_text(stage / name, text)
            write_json(stage / METRICS, {**head, "split": "val", **metrics})
            evaluator.write_artefacts(evaluation, stage)
        log.info("wrote %s (the validation split)", out_dir / METRICS)
    return metrics
