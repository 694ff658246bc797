"""``python -m studies.canonical.pooled``: the command that ``studies/canonical/LOG.md`` and ``studies/body/LOG.md``
ran, kept so that their commands still run; today it is ``lit3d-summary --pooled`` (the same code,
:mod:`lit3d.cli.summary_canonical`, :func:`lit3d.canonical.pooled.run`)::

    python -m studies.canonical.pooled RUN_DIR... --seeds 0 1 2 3 4 --out DIR
    = lit3d-summary --pooled RUN_DIR... --seeds 0 1 2 3 4 --out DIR
"""
from __future__ import annotations

import sys

from lit3d.cli import summary_canonical

PROG = "python -m studies.canonical.pooled"


def main(argv: list[str] | None = None) -> int:
    """``lit3d-summary --pooled`` with the run dirs as the leading arguments."""
    return summary_canonical.main(["--pooled", *(sys.argv[1:] if argv is None else argv)], PROG)


if __name__ == "__main__":
    sys.exit(main())
