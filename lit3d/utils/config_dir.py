"""Where the Hydra configs are: one answer for every entry point and study module."""
from __future__ import annotations

from pathlib import Path


def config_dir() -> Path:
    """The Hydra config dir: the repository's top-level ``conf/`` in a checkout (editable install),
    else the copy a wheel ships as ``lit3d/conf/`` (package data; in the repository ``lit3d/conf``
    is a symlink to ``../conf``)."""
    package = Path(__file__).resolve().parents[1]
    repo = package.parent
    if (repo / "pyproject.toml").is_file() and (repo / "conf").is_dir():
        return repo / "conf"
    return package / "conf"
