"""``python -m lit3d.api export CKPT OUT.pt [--device cpu]``: TorchScript of a checkpoint's net
(:func:`lit3d.api.export.export`). A bad checkpoint or output path (the checkpoint itself, any other
checkpoint, a folder) is one line on stderr, exit status 2; nothing is written then."""
from __future__ import annotations

import argparse
import sys

from lit3d.api.checkpoints import load
from lit3d.api.export import check_export_path, export
from lit3d.utils.checkpoints import first_line
from lit3d.utils.quiet import install


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m lit3d.api", description=__doc__.split("\n\n")[0])
    commands = parser.add_subparsers(dest="command", required=True)
    p = commands.add_parser("export", help="TorchScript of a completion or canonical checkpoint's net")
    p.add_argument("ckpt", help="completion or canonical checkpoint (lit3d-train)")
    p.add_argument("out", help="TorchScript file to write (.pt)")
    p.add_argument("--device", default="cpu", help="device the trace runs on (default cpu)")
    args = parser.parse_args(argv)
    install()
    try:
        check_export_path(args.out, args.ckpt)  # before the checkpoint is loaded: never over a checkpoint
        print(export(load(args.ckpt, args.device), args.out))
    except ValueError as exc:  # InputError, OutputError, QualityCheckpointError: one line naming the file
        print(f"python -m lit3d.api export: error: {first_line(exc)}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
