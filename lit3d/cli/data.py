"""``lit3d-data task=NAME [data=NAME data.root=PATH] [--show N]``: prepare a dataset ahead of training.

Generates the synthetic set (or indexes and converts a real one) into
``paths.data_dir``, prints counts per split and category, sizes and the
manifest hash as JSON, and writes the same JSON to ``data_summary.json`` in the run dir; ``--show N``
writes a PNG of N samples into the run dir. stdout holds the JSON alone (log and console lines go to
stderr while it runs), so ``lit3d-data ... > summary.json`` is valid JSON too. A ``data_dir`` holding
data of another config is refused (nothing deleted); ``--rebuild`` deletes it and prepares it
again (the only command that deletes prepared data; see docs/resuming.md). Ctrl-C or SIGTERM stops
the preparation at the next item, exit 143 with one line; the same command again resumes
(:mod:`lit3d.cli.stops`).
"""
from __future__ import annotations

import contextlib
import json
import logging
import sys
from collections.abc import Iterator
from pathlib import Path

import hydra
from omegaconf import DictConfig

from lit3d.cli.common import cli_main, run_cli
from lit3d.runtime.build import build_datamodule
from lit3d.runtime.compose import CONF_DIR
from lit3d.cli.stops import preparing
from lit3d.utils.io import write_json

SUMMARY = "data_summary.json"  # in the run dir: the printed JSON


@contextlib.contextmanager
def console_on_stderr() -> Iterator[None]:
    """Point the root logger's stdout handlers (Hydra's console handler) at stderr for the block, so
    that stdout keeps the one JSON document; restored afterwards."""
    moved = [h for h in logging.getLogger().handlers
             if isinstance(h, logging.StreamHandler) and getattr(h, "stream", None) is sys.stdout]
    for handler in moved:
        handler.setStream(sys.stderr)
    try:
        yield
    finally:
        for handler in moved:
            handler.setStream(sys.stdout)


def prepare(cfg: DictConfig) -> dict:
    """Prepare ``cfg.data``; print its description (JSON, stdout) and write it to the run dir's
    ``data_summary.json``; ``show`` samples to ``<task>_samples.png`` there."""
    out_dir = Path(cfg.paths.output_dir)
    with console_on_stderr():
        dm = build_datamodule(cfg.data)
        with preparing(dm.data_dir):  # Ctrl-C: stop at the next item
            dm.prepare_data()
        dm.setup("fit")
        info = json.loads(json.dumps(dm.describe(), default=str))
        write_json(out_dir / SUMMARY, info)
        n_show = int(cfg.get("show", 0) or 0)
        if n_show > 0:
            path = out_dir / f"{cfg.task_info.name}_samples.png"
            dm.show(n_show, path)
            print(f"wrote {path} and {out_dir / SUMMARY}", file=sys.stderr)
        else:
            print(f"wrote {out_dir / SUMMARY}", file=sys.stderr)
    print(json.dumps(info, indent=2, sort_keys=True), flush=True)
    return info


def _argv_show_to_override(argv: list[str]) -> list[str]:
    """Turn ``--show N`` into the Hydra override ``+show=N``."""
    out, i = [], 0
    while i < len(argv):
        if argv[i] == "--show" and i + 1 < len(argv):
            out.append(f"+show={argv[i + 1]}")
            i += 2
        elif argv[i].startswith("--show="):
            out.append("+show=" + argv[i].split("=", 1)[1])
            i += 1
        else:
            out.append(argv[i])
            i += 1
    return out


@hydra.main(version_base="1.3", config_path=CONF_DIR, config_name="train")
def _hydra_main(cfg: DictConfig) -> None:
    run_cli(prepare, cfg)


def main() -> None:
    """Console script ``lit3d-data`` (``--debug``: tracebacks instead of one-line errors; ``--rebuild``:
    delete the prepared data of ``data.data_dir`` and prepare it again, also when it is of another config)."""
    argv = sys.argv[1:]
    if "--rebuild" in argv:
        from datamodules.cache import request_rebuild

        argv = [a for a in argv if a != "--rebuild"]
        request_rebuild()
    cli_main(_hydra_main, _argv_show_to_override(argv), command="data")


if __name__ == "__main__":
    main()
