"""The optional extras of ``pip install lit3d`` and the one-line error that names the missing one.

``pip install lit3d`` gives the completion and quality tasks (training, ``lit3d-score``), the canonical
task on its procedural and mesh data, and ``lit3d-reconstruct``. Each extra below adds one feature's
dependencies (``pip install 'lit3d[body,wandb]'``; ``lit3d[all]``: every one):

    body         the Anny body model (anny, warp-lang, roma): lit3d-reconstruct --body, data.source.kind=anny
                 (experiment=canonical_humans, canonical_people), the body regressor
    slurm        Hydra's submitit launcher: hydra/launcher=slurm | slurm_local
    wandb        Weights & Biases: logger=wandb (lit3d-train's default logger when it is installed)
    tensorboard  TensorBoard: logger=tensorboard
    optuna       Hydra's Optuna sweeper: hparams_search=completion_optuna | canonical_optuna

A feature whose extra is missing calls :func:`require` before it starts; :class:`MissingExtra` is then one
line, e.g. ``--body needs the Anny body model: pip install 'lit3d[body]'`` (exit 2 in every command).
"""
from __future__ import annotations

import importlib.util
import sys

from lit3d.utils.errors import Lit3dError

# extra -> (the module whose absence means the extra is not installed, what it is in an error line)
EXTRAS: dict[str, tuple[str, str]] = {
    "body": ("anny", "the Anny body model"),
    "slurm": ("hydra_plugins.hydra_submitit_launcher", "Hydra's submitit launcher"),
    "wandb": ("wandb", "Weights & Biases (wandb)"),
    "tensorboard": ("tensorboard", "TensorBoard"),
    "optuna": ("hydra_plugins.hydra_optuna_sweeper", "Hydra's Optuna sweeper"),
}


class MissingExtra(Lit3dError, ImportError):
    """A feature whose optional dependencies are not installed; the message names the extra to install.
    An ``ImportError`` too, so code that caught the failed import still does."""


def installed(module: str) -> bool:
    """True when ``module`` can be imported (found on the path, without importing it; a module set to
    ``None`` in ``sys.modules`` counts as missing, as ``import`` treats it)."""
    if module in sys.modules:  # imported already (a stand-in package without a spec too), or None: blocked
        return sys.modules[module] is not None
    try:
        return importlib.util.find_spec(module) is not None
    except (ImportError, ValueError):  # a parent package missing, or a module without a spec
        return False


def has_extra(extra: str) -> bool:
    """True when the extra ``extra`` (a key of :data:`EXTRAS`) is installed."""
    return installed(EXTRAS[extra][0])


def missing_extra(extra: str, what: str) -> MissingExtra:
    """The error for ``what`` (the option or feature the user asked for) needing ``extra``."""
    module, name = EXTRAS[extra]
    return MissingExtra(f"{what} needs {name}: pip install 'lit3d[{extra}]'")


def require(extra: str, what: str) -> None:
    """Raise :class:`MissingExtra` (``<what> needs <name>: pip install 'lit3d[<extra>]'``) unless the
    extra ``extra`` is installed."""
    if not has_extra(extra):
        raise missing_extra(extra, what)
