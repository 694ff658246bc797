"""Interruption safety for ``lit3d-train``: a usable ``last.ckpt`` at any moment, with the RNG state.

:class:`ResumeState` (in ``conf/callbacks/default.yaml``):

- saves ``<dirpath>/last.ckpt`` every ``every_n_train_batches`` training batches, mid-epoch,
  so a hard kill (SIGKILL, OOM killer, power loss) loses at most that many batches, and at the
  end of every training epoch and of the training (Lightning's ``ModelCheckpoint(save_last=True)``
  writes ``last`` only when a top-k checkpoint is saved: with a flat validation metric it lagged
  epochs behind), so ``last.ckpt`` always holds the newest state;
- after a run dir was moved (or copied), points the checkpoint callbacks' saved paths (best,
  last, top-k) at the new ``checkpoints/`` when resuming, so the resumed run goes on writing
  ``last.ckpt`` (not ``last-v1.ckpt`` beside a stale one) and keeps its best checkpoint;
- saves ``last.ckpt`` when the run is stopped by SIGTERM (Lightning finishes the current
  batch, then raises ``SIGTERMException``) or Ctrl-C (``lit3d.cli.train.fit`` turns the first
  SIGINT into the same flag, so Ctrl-C also ends with exit 143 and the resume line);
- carries the Python, NumPy and torch (CPU and CUDA) RNG states in its checkpoint state
  and restores them on resume, so the resumed run continues the random streams of the
  saved one instead of restarting them from the seed.

``lit3d-train ... ckpt_path=last`` then resumes at the saved epoch and batch with the
weights, optimizer (and LR scheduler) states, loop counters and callback states (e.g. the
canonical task's loss phase). Lightning resumes a mid-epoch checkpoint by running the
remaining batches of that epoch from a fresh shuffle (the batches of the interrupted epoch
are not replayed one for one; the train loaders are not resumable samplers).

:class:`AtomicCheckpointIO` makes every checkpoint write atomic (temp file in the same folder
+ ``os.replace``), so a kill during a save leaves the previous ``last.ckpt`` intact, never
half a file. Lightning's own writer moves a temp file from ``/tmp``, which is a copy (not
atomic) when ``/tmp`` is another file system.
"""
from __future__ import annotations

import io
import os
import random
from pathlib import Path
from typing import Any

import lightning.pytorch as pl
import numpy as np
import torch
from lightning.pytorch.plugins.io import TorchCheckpointIO
from lightning.pytorch.trainer.states import TrainerFn
from lightning.pytorch.utilities.exceptions import SIGTERMException

from lit3d.utils.io import atomic_write_bytes, remove_temp_files


# ------------------------------------------------------------------ RNG state
def rng_state() -> dict[str, Any]:
    """Python, NumPy and torch RNG states as checkpoint-safe values (tuples, ints, tensors)."""
    kind, keys, pos, has_gauss, gauss = np.random.get_state()
    state = {
        "python": random.getstate(),
        "numpy": {"kind": kind, "keys": torch.from_numpy(keys.astype(np.int64)), "pos": int(pos),
                  "has_gauss": int(has_gauss), "gauss": float(gauss)},
        "torch": torch.get_rng_state(),
    }
    if torch.cuda.is_available() and torch.cuda.is_initialized():
        state["cuda"] = torch.cuda.get_rng_state_all()
    return state


def set_rng_state(state: dict[str, Any]) -> None:
    """Restore what :func:`rng_state` returned (also after ``torch.load(weights_only=True)``)."""
    version, internal, gauss = state["python"]
    random.setstate((version, tuple(internal), gauss))
    n = state["numpy"]
    np.random.set_state((n["kind"], n["keys"].numpy().astype(np.uint32), n["pos"], n["has_gauss"], n["gauss"]))
    torch.set_rng_state(state["torch"])
    if "cuda" in state and torch.cuda.is_available():
        torch.cuda.set_rng_state_all(state["cuda"])


# ------------------------------------------------------------------ checkpoint IO
class AtomicCheckpointIO(TorchCheckpointIO):
    """``torch.save`` into memory, then temp file next to the target + ``os.replace``."""

    def save_checkpoint(self, checkpoint: dict[str, Any], path, storage_options: Any | None = None) -> None:
        if storage_options is not None:
            raise TypeError(f"{type(self).__name__} does not take storage_options")
        buf = io.BytesIO()
        torch.save(checkpoint, buf)
        atomic_write_bytes(path, buf.getvalue())


# ------------------------------------------------------------------ moved run dirs
def _same_file(a, b) -> bool:
    """One path, however written (relative, ``./``, symlinked folders)."""
    return bool(a) and bool(b) and os.path.realpath(a) == os.path.realpath(b)


PATH_KEYS = ("best_model_path", "kth_best_model_path", "last_model_path")


def moved_paths(state: dict[str, Any], new_dir: str) -> dict[str, Any]:
    """Rewrite a ModelCheckpoint state (``dirpath``, best/kth/last paths, ``best_k_models`` keys)
    from its recorded ``dirpath`` to ``new_dir``, in place; unchanged when the folder is the same."""
    old = state.get("dirpath")
    if not old or str(old) == new_dir:
        return state

    def move(p):
        if isinstance(p, str) and p.startswith(str(old).rstrip("/") + "/"):
            return str(Path(new_dir) / Path(p).relative_to(old))
        return p

    for key in PATH_KEYS:
        if key in state:
            state[key] = move(state[key])
    if isinstance(state.get("best_k_models"), dict):
        state["best_k_models"] = {move(k): v for k, v in state["best_k_models"].items()}
    state["dirpath"] = new_dir
    return state


# ------------------------------------------------------------------ callback
class ResumeState(pl.Callback):
    """Keeps ``<dirpath>/<filename>`` current (every N batches, on SIGTERM/Ctrl-C) and carries the RNG state.

    Args:
        dirpath: checkpoint folder (``${paths.output_dir}/checkpoints``).
        every_n_train_batches: save after every N training batches (0: only on SIGTERM/Ctrl-C).
        filename: the file ``ckpt_path=last`` resumes from.
    """

    def __init__(self, dirpath: str, every_n_train_batches: int = 100, filename: str = "last.ckpt"):
        if every_n_train_batches < 0:
            raise ValueError(f"every_n_train_batches must be >= 0, got {every_n_train_batches}")
        self.dirpath = Path(dirpath)
        self.every_n_train_batches = int(every_n_train_batches)
        self.filename = filename
        self.saves = 0
        self._batches_seen = 0  # training batches since this process started
        self._saved_step: int | None = None  # global step of this process's last save

    @property
    def path(self) -> Path:
        return self.dirpath / self.filename

    def _save(self, trainer: pl.Trainer) -> None:
        if trainer.fast_dev_run or trainer.sanity_checking:
            return
        self._adopt_last(trainer)
        # the full state (optimizers, loops, callbacks): what `ckpt_path=last` resumes from; said
        # explicitly, else Lightning logs "`weights_only` was not set" at every save
        trainer.save_checkpoint(self.path, weights_only=False)
        self.saves += 1
        self._saved_step = getattr(trainer, "global_step", None)

    def _current(self, trainer: pl.Trainer) -> bool:
        """``last.ckpt`` already holds this step: saved here, or by a ModelCheckpoint writing it."""
        if self._saved_step == trainer.global_step:
            return True
        return any(getattr(cb, "_last_global_step_saved", None) == trainer.global_step and
                   _same_file(getattr(cb, "last_model_path", ""), self.path)
                   for cb in getattr(trainer, "checkpoint_callbacks", []))

    def _adopt_last(self, trainer: pl.Trainer) -> None:
        """Tell a ``ModelCheckpoint(save_last=True)`` writing to the same file that it is its own,
        so that it overwrites it instead of writing ``last-v1.ckpt`` beside it."""
        from lightning.pytorch.callbacks import ModelCheckpoint

        for cb in getattr(trainer, "checkpoint_callbacks", []):
            if isinstance(cb, ModelCheckpoint) and cb.save_last and cb.dirpath is not None and \
                    _same_file(Path(cb.dirpath) / f"{cb.CHECKPOINT_NAME_LAST}{cb.FILE_EXTENSION}", self.path):
                cb.last_model_path = os.path.join(cb.dirpath, f"{cb.CHECKPOINT_NAME_LAST}{cb.FILE_EXTENSION}")

    def setup(self, trainer, pl_module, stage: str) -> None:
        if stage == "fit" and trainer.is_global_zero:
            remove_temp_files(self.dirpath)  # a save cut short by SIGKILL leaves only a temp file

    def on_train_batch_end(self, trainer, pl_module, outputs, batch, batch_idx: int) -> None:
        # counted over the whole run, not per epoch: epochs shorter than N batches still save
        self._batches_seen += 1
        n = self.every_n_train_batches
        if n and self._batches_seen % n == 0:
            self._save(trainer)

    def on_train_epoch_end(self, trainer, pl_module) -> None:
        if not self._current(trainer):
            self._save(trainer)

    def on_train_end(self, trainer, pl_module) -> None:
        if not self._current(trainer):  # e.g. max_steps reached mid-epoch
            self._save(trainer)

    def on_train_start(self, trainer, pl_module) -> None:
        self._adopt_last(trainer)  # a resumed run overwrites its last.ckpt, never writes last-v1.ckpt

    def on_load_checkpoint(self, trainer, pl_module, checkpoint: dict[str, Any]) -> None:
        """Before the callbacks' states are loaded: where the run dir moved since the checkpoint was
        written, rewrite the ModelCheckpoint states' paths to the new folder (see the module doc)."""
        from lightning.pytorch.callbacks import ModelCheckpoint

        states = checkpoint.get("callbacks") or {}
        for cb in getattr(trainer, "checkpoint_callbacks", []):
            state = states.get(cb.state_key) if isinstance(cb, ModelCheckpoint) and cb.dirpath else None
            if isinstance(state, dict):
                moved_paths(state, str(cb.dirpath))

    def on_exception(self, trainer, pl_module, exception: BaseException) -> None:
        if isinstance(exception, (SIGTERMException, KeyboardInterrupt)) and trainer.state.fn == TrainerFn.FITTING:
            self._save(trainer)

    def state_dict(self) -> dict[str, Any]:
        return {"rng": rng_state()}

    def load_state_dict(self, state_dict: dict[str, Any]) -> None:
        if "rng" in state_dict:
            set_rng_state(state_dict["rng"])
