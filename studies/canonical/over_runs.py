"""``python -m studies.canonical.over_runs``: the command that ``studies/canonical/LOG.md`` ran, kept so that its
commands still run; today it is ``lit3d-summary --over-runs`` (the same code, :mod:`lit3d.cli.summary_canonical`,
:mod:`lit3d.canonical.over_runs`)::

    python -m studies.canonical.over_runs SWEEP_DIR... [--rows model input] [--out FILE.md] [--confusion model]
    = lit3d-summary --over-runs SWEEP_DIR... [--rows model input] [--out FILE.md] [--confusion model]
"""
from __future__ import annotations

import sys

from lit3d.cli import summary_canonical

PROG = "python -m studies.canonical.over_runs"


def main(argv: list[str] | None = None) -> int:
    """``lit3d-summary --over-runs`` with the sweep dirs as the leading arguments."""
    return summary_canonical.main(["--over-runs", *(sys.argv[1:] if argv is None else argv)], PROG)


if __name__ == "__main__":
    sys.exit(main())
