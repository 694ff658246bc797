"""The Hydra entry points called in-process (as their console scripts would run them), and the context
the table of bad-input cases hands each one."""
from __future__ import annotations

import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest


@dataclass
class Outcome:
    code: int | str     # exit status, or the exception type name for library loaders
    err: str            # stderr (or "error: <exception message>")


def hydra_entry(module: str, prog: str):
    """A Hydra console script called in-process (``sys.argv`` = prog + the option)."""
    def entry(arg, ctx: Ctx) -> Outcome:
        import importlib

        main = importlib.import_module(module).main
        ctx.monkeypatch.setattr(sys, "argv", [prog, *str(arg).split()])
        with pytest.raises(SystemExit) as info:
            main()
        return Outcome(info.value.code, ctx.capsys.readouterr().err)
    entry.__name__ = prog
    return entry


train_cli = hydra_entry("lit3d.cli.train", "lit3d-train")


eval_cli = hydra_entry("lit3d.cli.evaluate", "lit3d-eval")


data_cli = hydra_entry("lit3d.cli.data", "lit3d-data")


@dataclass
class Ctx:  # what an entry point of the table gets: tmp_path, pytest's capsys, monkeypatch, compose_cfg
    tmp: Path; capsys: Any; monkeypatch: Any; compose: Callable  # noqa: E702
