"""The one place where lit3d silences warnings and log lines that it cannot fix itself.

Every entry point (``lit3d-train``, ``lit3d-eval``, ``lit3d-data``, ``lit3d-score``,
``lit3d-reconstruct``, ``lit3d-summary``) calls :func:`install` before any work, and the tests
apply the same filters (``tests/conftest.py``: :func:`install` and :func:`pytest_filters`), so a warning is
either fixed at its source or listed here with the reason it cannot be. A warning caused by lit3d's own code or configs is
fixed where it arises, never added here.

Fixed at the source instead (for the record): Lightning's per-save "``weights_only`` was not
set" line (``ResumeState`` passes ``weights_only=False``), torchmetrics' "``compute`` called
before ``update``" (the completion module skips metrics that saw no batch), W&B's "the
anonymous setting has no effect" (``lit3d-train`` drops the ``anonymous`` argument that
Lightning's ``WandbLogger`` always passes).

This module imports nothing but the standard library (no Lightning: see the layer contracts).
"""
from __future__ import annotations

import logging
import re
import warnings

# (message regex, warning category, why lit3d cannot fix it)
WARNING_FILTERS: tuple[tuple[str, type[Warning], str], ...] = (
    (r"`isinstance\(treespec, LeafSpec\)` is deprecated", FutureWarning,
     "Lightning's own pytree helper (lightning/pytorch/utilities/_pytree.py) builds LeafSpec(), "
     "which torch 2.13 deprecates; raised inside every Trainer loop, no lit3d code involved"),
    (r"`training_step` returned `None`\. If this was on purpose", UserWarning,
     "task.on_nonfinite=skip skips a step whose loss is NaN/Inf by returning None, Lightning's "
     "documented way to skip an automatic-optimisation step; Lightning warns about it all the same"),
)

# (logger name, message regex, why): records of that logger whose message matches are dropped
LOG_FILTERS: tuple[tuple[str, str, str], ...] = (
    ("lightning.pytorch.utilities.rank_zero", r"^\W*Tip: ",
     "Lightning's advertisement for its cloud services (litlogger, litmodels), printed by every "
     "Trainer whatever its loggers; no setting turns it off"),
)

# (logger name, level, why): the logger is raised to that level
LOG_LEVELS: tuple[tuple[str, int, str], ...] = (
    ("OpenGL.acceleratesupport", logging.WARNING,
     "PyOpenGL says at INFO that its optional C speed-up (OpenGL_accelerate) is not installed; "
     "lit3d renders through EGL and does not need it"),
    ("trimesh", logging.WARNING,
     "trimesh logs at INFO for every OBJ part made of polygons ('triangulating faces') and similar "
     "loader notes; a folder of real CAD models prints hundreds of them, none asking for action"),
)


class _DropMatching(logging.Filter):
    """Drop the records whose message matches ``pattern``."""

    def __init__(self, pattern: str):
        super().__init__()
        self.pattern = re.compile(pattern)

    def filter(self, record: logging.LogRecord) -> bool:
        return not self.pattern.search(record.getMessage())


def pytest_filters() -> list[str]:
    """:data:`WARNING_FILTERS` as pytest ``filterwarnings`` lines (``tests/conftest.py`` adds them, so
    they hold in every test's setup, call and teardown, module-scoped fixtures included)."""
    lines = []
    for message, category, _why in WARNING_FILTERS:
        if ":" in message:
            raise ValueError(f"warning filter {message!r}: pytest splits filterwarnings lines at ':'")
        name = category.__name__ if category.__module__ == "builtins" else f"{category.__module__}.{category.__qualname__}"
        lines.append(f"ignore:{message}:{name}")
    return lines


def install() -> None:
    """Apply the filters above (idempotent: calling it again adds nothing)."""
    for message, category, _why in WARNING_FILTERS:
        warnings.filterwarnings("ignore", message=message, category=category)
    for name, pattern, _why in LOG_FILTERS:
        logger = logging.getLogger(name)
        if not any(isinstance(f, _DropMatching) and f.pattern.pattern == pattern for f in logger.filters):
            logger.addFilter(_DropMatching(pattern))
    for name, level, _why in LOG_LEVELS:
        logger = logging.getLogger(name)
        if logger.level < level:
            logger.setLevel(level)
