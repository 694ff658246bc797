"""``lit3d-summary experiment=NAME``: parameters, output shapes and activation memory per component.

Nets are built on the meta device, so paper-scale configs cost no memory. ``lit3d-summary --pooled`` and
``lit3d-summary --over-runs``: the canonical task's cross-validation summaries (:mod:`lit3d.cli.summary_canonical`).
"""
from __future__ import annotations

import sys

import hydra
from omegaconf import DictConfig

from lit3d.cli import summary_canonical
from lit3d.cli.common import cli_main, run_cli
from lit3d.runtime.build import _construct, import_object, task_kwargs
from lit3d.runtime.compose import CONF_DIR
from lit3d.runtime.errors import UserError
from lit3d.utils.checkpoints import first_line


def summary_rows(task_cfg: DictConfig) -> list[dict]:
    """The task's per-component rows, its nets built on the meta device. A bad size gives the one
    line ``lit3d-train`` gives (``task config: ...``, :class:`UserError`); a net that cannot run at
    the configured sizes (a shape error in the meta forward, e.g. ``task.net.image_size`` too small
    for its pooling levels) gives ``task config: the nets do not run at these sizes (...)``."""
    import torch

    task_cls = import_object(task_cfg["_target_"])
    try:
        with torch.device("meta"):
            return _construct("task", lambda: task_cls.summary_rows(task_kwargs(task_cfg)))
    except RuntimeError as exc:
        raise UserError(f"task config: the nets do not run at these sizes ({first_line(exc, 'RuntimeError')})") from exc


def summary(cfg: DictConfig) -> str:
    from lit3d.utils.summary import format_summary_table

    rows = summary_rows(cfg.task)
    text = f"# {cfg.task_info.name}: per-component summary (batch 1, meta device)\n\n" + format_summary_table(rows)
    print(text)
    return text


@hydra.main(version_base="1.3", config_path=CONF_DIR, config_name="train")
def hydra_main(cfg: DictConfig) -> None:
    run_cli(summary, cfg)


def main(argv: list[str] | None = None) -> None:
    """Console script ``lit3d-summary`` (``--debug``: tracebacks instead of one-line errors); ``--pooled`` and
    ``--over-runs``: :mod:`lit3d.cli.summary_canonical` (exits with its status)."""
    argv = sys.argv[1:] if argv is None else list(argv)
    status = summary_canonical.main(argv)
    if status is not None:
        sys.exit(status)
    cli_main(hydra_main, argv, command="summary")


if __name__ == "__main__":
    main()
