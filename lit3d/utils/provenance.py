"""What made a run: the lit3d version, the git commit of the checkout, the data's manifest hash.

Stored in every checkpoint (``checkpoint["lit3d"]["provenance"]``, by
:class:`lit3d.callbacks.metadata.MetadataCallback`) and in every ``metrics.json``
(``"provenance"``)::

    {"lit3d_version": "0.1.0", "git_commit": "324a24f...", "git_dirty": false,
     "manifest_hash": "9c1e...", "data_config_hash": "41d0..."}

``git_commit`` and ``git_dirty`` are None where lit3d does not run from a git checkout (a wheel
install) or git is not installed; ``manifest_hash`` / ``data_config_hash`` are None where no
prepared data was involved (a checkpoint written by :func:`lit3d.api.untrained_checkpoint`).
Standard library only: :data:`lit3d.__version__` reads its version here without importing torch.
"""
from __future__ import annotations

import json
import re
import subprocess
from functools import lru_cache
from importlib import metadata
from pathlib import Path

from lit3d.utils.data_hooks import HasManifest
from lit3d.utils.io import write_json

PACKAGE_DIR = Path(__file__).resolve().parents[1]  # lit3d/
UNKNOWN_VERSION = "0+unknown"


def lit3d_version() -> str:
    """The installed distribution's version (``importlib.metadata``); where lit3d is not installed
    (imported from a source tree), the ``version`` of the ``pyproject.toml`` beside the package."""
    try:
        return metadata.version("lit3d")
    except metadata.PackageNotFoundError:
        return pyproject_version(PACKAGE_DIR.parent / "pyproject.toml")


def pyproject_version(path: Path) -> str:
    """``[project] version`` of a ``pyproject.toml`` (:data:`UNKNOWN_VERSION` when absent)."""
    try:
        text = path.read_text(encoding="utf-8")
    except OSError:
        return UNKNOWN_VERSION
    project = re.search(r"^\[project\]\s*$(.*?)(?=^\[|\Z)", text, re.M | re.S)
    found = re.search(r'^version\s*=\s*"([^"]+)"', project.group(1), re.M) if project else None
    return found.group(1) if found else UNKNOWN_VERSION


def _git(root: Path, *args: str) -> str | None:
    """``git -C root ARGS`` stdout (stripped); None when git is missing or fails."""
    try:
        out = subprocess.run(["git", "-C", str(root), *args], capture_output=True, text=True, timeout=20)
    except (OSError, subprocess.SubprocessError):
        return None
    return out.stdout.strip() if out.returncode == 0 else None


@lru_cache(maxsize=4)
def git_state(root: Path = PACKAGE_DIR.parent) -> tuple[str | None, bool | None]:
    """``(commit, dirty)`` of the git checkout at ``root`` (tracked files changed since the commit ->
    dirty); ``(None, None)`` unless ``root`` itself holds a ``.git`` (a wheel's site-packages does
    not, even inside another repository) and git answers."""
    if not (root / ".git").exists():
        return None, None
    commit = _git(root, "rev-parse", "HEAD")
    if commit is None:
        return None, None
    status = _git(root, "status", "--porcelain", "--untracked-files=no")
    return commit, None if status is None else bool(status)


def code_provenance() -> dict:
    """``{"lit3d_version", "git_commit", "git_dirty"}`` of the running code (plain values)."""
    commit, dirty = git_state()
    return {"lit3d_version": lit3d_version(), "git_commit": commit, "git_dirty": dirty}


def data_provenance(datamodule) -> dict:
    """``{"manifest_hash", "data_config_hash"}`` of a set-up lit3d DataModule (its ``manifest``:
    :mod:`datamodules.cache`); None values for None or a DataModule not yet set up."""
    manifest = datamodule.manifest if isinstance(datamodule, HasManifest) else None
    manifest = manifest if isinstance(manifest, dict) else {}
    return {"manifest_hash": manifest.get("manifest_hash"), "data_config_hash": manifest.get("config_hash")}


def provenance(datamodule=None) -> dict:
    """:func:`code_provenance` plus :func:`data_provenance` of ``datamodule``."""
    return {**code_provenance(), **data_provenance(datamodule)}


def add_to_metrics(path: str | Path, record: dict) -> Path:
    """Set ``"provenance": record`` in the ``metrics.json`` at ``path`` (rewritten atomically; for a
    writer that learns the data's manifest only after the file was written, as ``lit3d-eval``)."""
    path = Path(path)
    return write_json(path, {**json.loads(path.read_text()), "provenance": record})
