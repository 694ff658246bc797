"""One process per run dir (``lit3d-train``, ``lit3d-eval``, ``lit3d-data``).

Before Hydra writes anything into the run dir (``.hydra/``, ``train.log``), :func:`claim_run_dir`

- gives a timestamped run dir (the default ``hydra.run.dir``, ``.../runs/<time>``) that another
  run started in the same second already made a suffix: ``<time>_2``, ``<time>_3`` ... (an atomic
  ``mkdir``; the claimed dir is handed to Hydra as ``hydra.run.dir=...``);
- takes the run dir's lock (``flock`` on ``<run dir>/.lit3d.lock``) for the whole process, and
  clears what killed runs left in it and in the run dirs beside it (:mod:`lit3d.cli.run_leftovers`). A
  second run into a busy dir is refused with one line naming the holder (pid, host, start
  time), or waits for it with ``wait_for_run_dir=true``. The system frees the lock when the
  holder exits, SIGKILL included.

A run that waited never replaces the results the run it waited for left in the dir
(:func:`check_waited`): ``metrics.json``, ``results.md``, ``config.yaml``, ``curves.png`` or a
checkpoint there stop it with one line naming the dir and those files, before Hydra writes
anything; a training that continues that run (``ckpt_path=last``, or a checkpoint of that dir)
goes on.

:func:`hold_output_dir` takes the same lock inside a Hydra job (the jobs of a multirun, where
the command line names no single run dir); it is a no-op where :func:`claim_run_dir` holds it.
The other processes of one distributed run (ranks > 0, which Lightning starts with the run
dir on their command line) share the dir of rank 0 and take no lock.
"""
from __future__ import annotations

import contextlib
import os
import re
import sys
from pathlib import Path

from omegaconf import DictConfig, OmegaConf

from lit3d.cli.run_leftovers import LOCK_FILE, clear_run_dirs
from lit3d.utils.io import OutputError
from lit3d.utils.locks import HeldLock, hold

RUN_DIR_KEY = "hydra.run.dir"
WAIT_KEY = "wait_for_run_dir"
_PLAIN = re.compile(r"[\w./:+@%~-]+")
RANK_VARS = ("LOCAL_RANK", "NODE_RANK", "RANK", "SLURM_PROCID")  # set by Lightning / torchrun / SLURM


def _other_rank() -> bool:
    """A process of a distributed run other than its first (it shares rank 0's run dir)."""
    return any(os.environ.get(v, "0").strip() not in ("", "0") for v in RANK_VARS)


def _busy(run_dir: Path):
    def message(holder: str) -> str:
        return (f"{run_dir}: run dir in use by {holder}; wait for that run to end, choose another "
                f"hydra.run.dir, or add {WAIT_KEY}=true to wait for it")
    return message


def _say_waiting(run_dir: Path):
    def say(holder: str) -> None:
        print(f"{run_dir}: run dir in use by {holder}; waiting for it ({WAIT_KEY}=true)", file=sys.stderr, flush=True)
    return say


def lock_run_dir(run_dir: str | os.PathLike, wait: bool = False) -> HeldLock:
    """Create ``run_dir`` and take its lock (see the module doc); raises
    :class:`~lit3d.utils.locks.LockBusy` (one line naming the holder) unless ``wait``. The lock's
    ``waited`` is True when another process held it first (this one waited for it)."""
    run_dir = Path(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    waited: list[str] = []
    say = _say_waiting(run_dir)

    def on_wait(holder: str) -> None:
        waited.append(holder)
        say(holder)

    lock = hold(run_dir / LOCK_FILE, _busy(run_dir), wait=wait, on_wait=on_wait)
    lock.waited = bool(waited)
    if lock.owner:  # what killed runs left here and beside it (lit3d.cli.run_leftovers)
        for note in clear_run_dirs(run_dir):
            print(f"note: {note}", file=sys.stderr, flush=True)
    return lock


RESULT_FILES = ("metrics.json", "results.md", "config.yaml", "curves.png")


def run_results(run_dir: str | os.PathLike) -> list[str]:
    """The results a run left in ``run_dir``: :data:`RESULT_FILES` and ``checkpoints/*.ckpt`` there."""
    run_dir = Path(run_dir)
    found = [name for name in RESULT_FILES if (run_dir / name).is_file()]
    ckpts = run_dir / "checkpoints"
    if ckpts.is_dir():
        found += [f"checkpoints/{p.name}" for p in sorted(ckpts.glob("*.ckpt"))]
    return found


def _continues(run_dir: Path, ckpt_path) -> bool:
    """A training resumed from ``run_dir``'s own checkpoint (``ckpt_path=last`` or a file under it)."""
    if ckpt_path in (None, "", "null"):
        return False
    if ckpt_path == "last":
        return True
    try:
        return Path(str(ckpt_path)).resolve().is_relative_to(run_dir.resolve())
    except OSError:
        return False


def check_waited(run_dir: str | os.PathLike, command: str, ckpt_path=None) -> None:
    """Raise :class:`~lit3d.utils.io.OutputError` when a ``command`` (``train``, ``eval``) that waited
    for ``run_dir`` would replace the results the run it waited for left there (:func:`run_results`);
    a training continuing that run (:func:`_continues`) and the commands that write no results
    (``data``, ``summary``) pass."""
    run_dir = Path(run_dir)
    found = run_results(run_dir)
    if command not in ("train", "eval") or not found or (command == "train" and _continues(run_dir, ckpt_path)):
        return
    shown = ", ".join(found[:5]) + (", ..." if len(found) > 5 else "")
    resume = (f"continue it with the same overrides plus hydra.run.dir={_override_value(run_dir)} ckpt_path=last, or "
              if command == "train" and (run_dir / "checkpoints" / "last.ckpt").is_file() else "")
    raise OutputError(f"{run_dir}: the run this one waited for left its results here ({shown}); a run started with "
                      f"{WAIT_KEY}=true never replaces them: {resume}choose another hydra.run.dir")


def new_dir(path: Path) -> Path:
    """``path`` or, when it exists already, ``path_2``, ``path_3`` ...: made here, atomically, so
    two processes never get the same one."""
    path.parent.mkdir(parents=True, exist_ok=True)
    candidate, k = path, 1
    while True:
        try:
            os.mkdir(candidate)
            return candidate
        except FileExistsError:
            k += 1
            candidate = path.with_name(f"{path.name}_{k}")


def _override_value(path: Path) -> str:
    text = str(path)
    if _PLAIN.fullmatch(text):
        return text
    return "'" + text.replace("\\", "\\\\").replace("'", "\\'") + "'"


def _multirun(cfg: DictConfig) -> bool:
    """A config that makes Hydra sweep without ``-m`` (``hydra.mode: MULTIRUN``, as the Optuna
    ``hparams_search`` configs set): its jobs run in the sweep dir, never in ``hydra.run.dir``."""
    try:
        return str(OmegaConf.select(cfg, "hydra.mode", default="") or "").rsplit(".", 1)[-1] == "MULTIRUN"
    except Exception:  # an interpolation only Hydra's runtime can resolve
        return False


def claim_run_dir(cfg: DictConfig | None, args: list[str],
                  command: str = "train") -> tuple[list[str], contextlib.AbstractContextManager]:
    """``(args, lock)``: the command line to hand to Hydra (plus ``hydra.run.dir=<claimed dir>``
    where the run dir is a fresh timestamped one) and the held lock of the run dir (release it by
    leaving ``with lock:``). ``cfg``: the composed config with its ``hydra`` node, or None
    (multirun, ``--cfg`` ...: nothing claimed here; :func:`hold_output_dir` locks each job's dir); a
    config with ``hydra.mode: MULTIRUN`` (an Optuna search without ``-m``) claims nothing either.
    ``command`` (``train``, ``eval``, ``data``, ``summary``): after a wait, :func:`check_waited`."""
    if cfg is None or _other_rank() or _multirun(cfg):
        return args, contextlib.nullcontext()
    try:
        raw = str(OmegaConf.to_container(cfg.hydra.run, resolve=False).get("dir", ""))
        run_dir = Path(str(OmegaConf.select(cfg, RUN_DIR_KEY)))
    except Exception:  # an interpolation only Hydra's runtime can resolve: Hydra handles the dir
        return args, contextlib.nullcontext()
    given = any(a.split("=", 1)[0].lstrip("+~") == RUN_DIR_KEY for a in args)
    if "${now:" in raw and not given:
        run_dir = new_dir(run_dir)
        args = [*args, f"{RUN_DIR_KEY}={_override_value(run_dir)}"]
    lock = lock_run_dir(run_dir, wait=bool(cfg.get(WAIT_KEY, False)))
    if lock.waited:
        try:
            check_waited(run_dir, command, cfg.get("ckpt_path"))
        except BaseException:
            lock.release()
            raise
    return args, lock


def hold_output_dir(cfg: DictConfig) -> contextlib.AbstractContextManager:
    """The lock of ``cfg.paths.output_dir`` (this Hydra job's dir, which Hydra made) for a ``with``
    block; a no-op when this process holds it already, or the config names no output dir or one
    that does not exist (a config composed outside Hydra's runtime: nothing is created here)."""
    try:
        out = OmegaConf.select(cfg, "paths.output_dir", default=None)
    except Exception:  # no Hydra runtime (a config composed in a test): nothing to lock
        return contextlib.nullcontext()
    if not out or _other_rank() or not Path(out).is_dir():
        return contextlib.nullcontext()
    return lock_run_dir(out, wait=bool(cfg.get(WAIT_KEY, False)))
