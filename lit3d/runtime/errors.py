"""The errors of the Hydra entry points that end a run with one line (:mod:`lit3d.cli.common`)."""
from __future__ import annotations

import signal

from lit3d.utils.errors import Lit3dError

EXIT_SIGTERM = 128 + signal.SIGTERM


class UserError(Lit3dError):
    """A problem the user can fix (bad path, missing option): printed as one line."""


class Interrupted(Exception):
    """Training was stopped by a signal after saving ``last.ckpt``; the message says how to resume."""

    exit_code = EXIT_SIGTERM
