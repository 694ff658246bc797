"""``lit3d-summary experiment=NAME``: parameters, output shapes and activation memory per component.

Nets are built on the meta device, so paper-scale configs cost no memory.
"""
from __future__ import annotations

import hydra
from omegaconf import DictConfig

from lit3d.cli.common import CONF_DIR, cli_main, import_object, run_cli, task_kwargs


def summary(cfg: DictConfig) -> str:
    import torch

    from lit3d.utils.summary import format_summary_table

    task_cls = import_object(cfg.task["_target_"])
    with torch.device("meta"):
        rows = task_cls.summary_rows(task_kwargs(cfg.task))
    text = f"# {cfg.task_info.name}: per-component summary (batch 1, meta device)\n\n" + format_summary_table(rows)
    print(text)
    return text


@hydra.main(version_base="1.3", config_path=CONF_DIR, config_name="train")
def hydra_main(cfg: DictConfig) -> None:
    run_cli(summary, cfg)


def main() -> None:
    """Console script ``lit3d-summary`` (``--debug``: tracebacks instead of one-line errors)."""
    cli_main(hydra_main)


if __name__ == "__main__":
    main()
