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


def exact_quotient(numerator, denominator) -> int | None:
    """``${exact_div:a,b}`` in the configs: ``a / b`` for integers that divide exactly (e.g. the completion
    input grid from ``data.target_res`` and ``data.input_factor``), so a size written once in the data
    config is read by the nets instead of being repeated; None when either is null (a config without data,
    e.g. ``lit3d-eval task=NAME``, whose net sizes come from the checkpoint)."""
    if numerator is None or denominator is None:
        return None
    a, b = int(numerator), int(denominator)
    if b <= 0 or a % b:
        raise ValueError(f"exact_div: {a} is not a whole multiple of {b}")
    return a // b


def register_resolvers() -> None:
    """Register the configs' resolvers with OmegaConf (idempotent; done when this module is imported,
    which every entry point does before composing a config)."""
    from omegaconf import OmegaConf

    if not OmegaConf.has_resolver("exact_div"):
        OmegaConf.register_new_resolver("exact_div", exact_quotient)


register_resolvers()
