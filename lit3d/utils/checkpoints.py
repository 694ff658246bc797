"""Safe checkpoint reading shared by the entry points (``lit3d-eval``, ``lit3d-train ckpt_path=``,
``lit3d-score --ckpt``). Imports torch only (no Lightning), so that it is cheap to use from
light command lines.

A checkpoint is loaded with ``weights_only=True``: one that pickles arbitrary Python objects
is refused, never executed.
"""
from __future__ import annotations

import pickle
import zipfile
from pathlib import Path

from lit3d.utils.files import path_problem

# where lit3d-train stores what evaluation needs (task, data config, W&B id) in every checkpoint
META_KEY = "lit3d"


def first_line(exc: BaseException, default: str = "") -> str:
    """The first non-empty line of ``str(exc)`` (``default`` when there is none)."""
    text = str(exc).strip()
    return text.splitlines()[0] if text else default


def load_checkpoint(path: str | Path, error: type[Exception] = ValueError) -> dict:
    """``torch.load(path, weights_only=True, mmap=True)`` on CPU; every failure is one ``error``
    naming the file: missing, a folder or FIFO (:func:`lit3d.utils.files.path_problem`), not a ``torch.save``
    zip archive, pickled objects refused, corrupt.
    """
    import torch

    path = Path(path)
    problem = path_problem(path, "checkpoint")  # a folder, a FIFO (never opened): named as such
    if problem is not None:
        raise error(f"{path}: {'checkpoint not found' if problem == 'no such checkpoint' else problem}")
    if not zipfile.is_zipfile(path):  # torch.save writes a zip archive; torch.load's own error here is about mmap
        raise error(f"{path}: not a readable checkpoint (not a torch.save zip archive)")
    try:
        return torch.load(path, map_location="cpu", weights_only=True, mmap=True)
    except pickle.UnpicklingError as exc:  # pickled objects that weights_only refuses (never executed)
        refused = [ln.strip() for ln in str(exc).splitlines() if "Unsupported" in ln]
        detail = refused[0].split(". ")[0] if refused else "UnpicklingError"
        raise error(f"{path}: not a readable checkpoint: refused to load pickled Python objects ({detail})") from exc
    except Exception as exc:  # corrupt archive, not a torch file
        raise error(f"{path}: not a readable checkpoint ({type(exc).__name__}: {first_line(exc)})") from exc


def is_checkpoint(path: str | Path) -> bool:
    """True when ``path`` is a file written by ``torch.save`` (a Lightning or torch checkpoint: a zip
    archive with ``<name>/data.pkl``), not a TorchScript archive (``torch.jit.save`` adds ``code/``
    and ``constants.pkl``); a file that cannot be read as a zip archive, a folder or a FIFO (never
    opened: it could block) is not one."""
    if not Path(path).is_file():
        return False
    try:
        with zipfile.ZipFile(path) as z:
            names = z.namelist()
    except (OSError, zipfile.BadZipFile, ValueError):
        return False
    parts = [n.split("/", 1)[-1] for n in names]
    return "data.pkl" in parts and "constants.pkl" not in parts and not any(n.startswith("code/") for n in parts)
