"""A full disk while a checkpoint, a data item or ``metrics.json`` is written.

``write()`` on a full disk raises ``OSError(ENOSPC)`` naming no file, so the entry points' handler of
file-system faults (``error: <path>: cannot write here (<problem>)``, exit 2) missed it and the user
got a traceback. The atomic writers (:func:`lit3d.utils.io.atomic_file`, behind
``atomic_write_bytes``, ``write_json``, ``atomic_save_npz`` and the checkpoint IO) now raise it again
naming the file they write.

The disk is made full for one kind of file by a patched ``os.fdopen`` (the atomic writers open their
temp file with it): ``write()`` of such a file raises ``OSError(ENOSPC, "No space left on device")``
without a file name, as the kernel's does. The entry points run in-process (``main()`` with
``sys.argv``, as the console scripts do).
"""
from __future__ import annotations

import errno
import os
import re
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from tests.helpers.runs import TINY_NETS

from datamodules.cache import atomic_save_npz
from lit3d.api.checkpoints import untrained_checkpoint
from lit3d.cli import data as data_cli
from lit3d.cli import evaluate as evaluate_cli
from lit3d.cli import train as train_cli
from lit3d.utils.io import atomic_write_bytes, write_json

NO_SPACE = "cannot write here (no space left on the device)"


class _FullDisk:
    """An open file whose ``write()`` fails as on a full disk; the rest is the real file's."""

    def __init__(self, f):
        self._f = f

    def write(self, data):
        raise OSError(errno.ENOSPC, "No space left on device")  # no file name, as the kernel's

    def __getattr__(self, name):
        return getattr(self._f, name)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self._f.close()


@pytest.fixture
def full_disk(monkeypatch) -> Callable[[Callable[[Path], bool]], None]:
    """``full_disk(pred)``: every file opened with ``os.fdopen`` whose path ``pred`` accepts is on a full disk."""
    real = os.fdopen

    def make_full(pred: Callable[[Path], bool]) -> None:
        def fdopen(fd, *args, **kwargs):
            f = real(fd, *args, **kwargs)
            try:
                path = Path(os.readlink(f"/proc/self/fd/{fd}"))
            except OSError:
                return f
            return _FullDisk(f) if pred(path) else f

        monkeypatch.setattr(os, "fdopen", fdopen)

    return make_full


def _main(module, args: list[str], monkeypatch, capsys) -> tuple[int, str]:
    """``module.main()`` with ``args`` as the command line: (exit status, last stderr line); no traceback."""
    monkeypatch.delenv("HYDRA_FULL_ERROR", raising=False)
    monkeypatch.setenv("OMP_NUM_THREADS", "1")
    monkeypatch.setattr(sys, "argv", [module.__name__, *args])
    with pytest.raises(SystemExit) as info:
        module.main()
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert "Traceback" not in err and [ln for ln in lines if ln.startswith("error:")] == lines[-1:], err[-3000:]
    return info.value.code, lines[-1]


def test_the_atomic_writers_name_the_file_on_a_full_disk(tmp_path, full_disk):
    full_disk(lambda p: p.parent == tmp_path)
    for write in (lambda p: atomic_write_bytes(p, b"x"), lambda p: write_json(p, {"a": 1}),
                  lambda p: atomic_save_npz(p, a=np.zeros(3))):
        target = tmp_path / "out.bin"
        with pytest.raises(OSError) as info:
            write(target)
        assert (info.value.errno, info.value.filename) == (errno.ENOSPC, str(target))
        assert list(tmp_path.iterdir()) == [], "a temp file (or a half-written file) was left"


def test_full_disk_while_writing_a_data_item(tmp_path, full_disk, monkeypatch, capsys):
    data = tmp_path / "data"
    full_disk(lambda p: "items" in p.parts and data in p.parents)
    code, line = _main(data_cli, ["experiment=completion_demo", "data.prepare.progress=false",
                                  "data.sizes={train:2,val:0,test_same:0,test_cross:0,test_unseen:0}",
                                  f"paths.data_dir={data}", f"hydra.run.dir={tmp_path}/run"], monkeypatch, capsys)
    items = data / "completion_demo" / "items"
    assert code == 2 and re.fullmatch(rf"error: {re.escape(str(items))}/train/[^/]+\.npz: {re.escape(NO_SPACE)}", line)
    assert not [p for p in items.rglob("*") if p.is_file()], "a half-written item was left"


def test_full_disk_while_saving_a_checkpoint(tmp_path, full_disk, monkeypatch, capsys):
    run = tmp_path / "run"
    full_disk(lambda p: p.parent == run / "checkpoints")
    code, line = _main(train_cli, ["experiment=completion_demo", "data.prepare.progress=false", "data.batch_size=2",
                                   "data.sizes={train:4,val:2,test_same:0,test_cross:0,test_unseen:0}", *TINY_NETS,
                                   "trainer.max_epochs=1", "logger=csv",
                                   "test_after_fit=false", "callbacks.progress_bar=null",
                                   f"paths.data_dir={tmp_path}/data", f"hydra.run.dir={run}"], monkeypatch, capsys)
    assert code == 2 and re.fullmatch(rf"error: {re.escape(str(run))}/checkpoints/[^/]+\.ckpt: {re.escape(NO_SPACE)}",
                                      line), line
    assert list((run / "checkpoints").iterdir()) == [], "a checkpoint or its temp file was left"


def test_full_disk_while_writing_metrics_json(tmp_path, full_disk, monkeypatch, capsys):
    """``lit3d-eval``: the line names ``<run dir>/metrics.json`` (not the hidden staging folder the
    evaluation writes into first), and no file of the evaluation is left in the run dir."""
    sizes = "data.sizes={train:2,val:2,test_same:2,test_cross:0,test_unseen:0}"
    ckpt = untrained_checkpoint("completion_demo", tmp_path / "c.ckpt",
                                [*TINY_NETS, sizes, "data.batch_size=2", "data.prepare.progress=false",
                                 f"paths.data_dir={tmp_path}/data"])
    run = tmp_path / "run"
    full_disk(lambda p: p.name.startswith(".metrics.json."))
    code, line = _main(evaluate_cli, [f"ckpt_path={ckpt}", "n_figures=0", f"hydra.run.dir={run}"], monkeypatch, capsys)
    assert (code, line) == (2, f"error: {run}/metrics.json: {NO_SPACE}")
    assert sorted(p.name for p in run.iterdir()) == [".hydra", ".lit3d.lock", "evaluate.log"]
