"""Collect the metrics.json of a multirun's jobs into ``sweep_results.md`` again, by hand (every
multirun does it when it ends: :class:`lit3d.sweeps.CollectResults`).

    python -m studies.sweeps.collect SWEEP_DIR [METRIC ...]
"""
from __future__ import annotations

import sys

from lit3d.sweeps import collect


def main(argv: list[str] | None = None) -> None:
    argv = sys.argv[1:] if argv is None else argv
    print(collect(argv[0], argv[1:] or None))


if __name__ == "__main__":
    main()
