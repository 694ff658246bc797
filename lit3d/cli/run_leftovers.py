"""The leftovers of killed runs in run dirs, removed by the next run.

A run killed outright (SIGKILL, the OOM killer, a power cut) cannot clean up: it may leave a
checkpoint's temp file (``checkpoints/.last.ckpt.<pid>-<host>.<random>.tmp``), an evaluation's
staging folder (``.evaluation.<pid>-<host>.<random>.tmp/``, or one whose set was half renamed), or
the temp file of ``metrics.json``, ``config.yaml`` or ``curves.png``. When ``lit3d-train``,
``lit3d-eval``, ``lit3d-data`` or ``lit3d-summary`` takes a run dir (:func:`lit3d.cli.rundir.lock_run_dir`),
:func:`clear_run_dirs` clears

- its own run dir: nothing else writes there while this process holds the lock, so every temp file
  and staging folder there is a leftover;
- the run dirs beside it (``logs/<task>/runs/*``, the jobs of one multirun) whose lock file names a
  holder that is gone: a process of this host that no longer runs (a run that ends in any other way
  empties its lock file and leaves nothing). Those of running processes and other hosts stay.

A staging folder whose set was committed (its journal written) has its renames finished rather
than removed (:func:`lit3d.utils.io.repair_sets`): the killed evaluation was complete.
"""
from __future__ import annotations

import re
import socket
from pathlib import Path

from lit3d.utils.io import TMP_SUFFIX, repair_sets
from lit3d.utils.temp_names import alive

LOCK_FILE = ".lit3d.lock"
CHECKPOINTS = "checkpoints"
_HOLDER = re.compile(r"pid (\d+) on (\S+) since ")


def clear_run_dir(run_dir: str | Path) -> list[str]:
    """Remove every temp file and staging folder in ``run_dir`` and its ``checkpoints/`` (a set that
    was committed is finished); for a run dir no process writes into. One note per thing handled."""
    run_dir = Path(run_dir)
    notes = repair_sets(run_dir, idle=True)
    ckpts = run_dir / CHECKPOINTS
    if ckpts.is_dir():
        for p in sorted(ckpts.glob(f".*{TMP_SUFFIX}")):
            if p.is_file():
                p.unlink(missing_ok=True)
                notes.append(f"{p}: removed the temp file of an interrupted write")
    return notes


def holder_gone(run_dir: str | Path) -> bool:
    """``run_dir``'s lock file names a holder on this host that no longer runs (a killed run)."""
    try:
        text = (Path(run_dir) / LOCK_FILE).read_text("utf-8", "replace")
    except OSError:
        return False
    m = _HOLDER.match(text.strip())
    return bool(m) and m[2] == socket.gethostname() and not alive(int(m[1]))


def clear_run_dirs(run_dir: str | Path) -> list[str]:
    """:func:`clear_run_dir` on ``run_dir`` (whose lock this process holds) and on each run dir beside
    it whose holder is gone (:func:`holder_gone`); the notes of what was removed."""
    run_dir = Path(run_dir)
    notes = clear_run_dir(run_dir)
    try:
        siblings = sorted(p for p in run_dir.parent.iterdir() if p != run_dir and (p / LOCK_FILE).is_file())
    except OSError:
        return notes
    for sib in siblings:
        if holder_gone(sib):
            notes += clear_run_dir(sib)
    return notes
