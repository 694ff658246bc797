"""What ``lit3d-eval`` needs, stored in every checkpoint under ``checkpoint["lit3d"]``."""
from __future__ import annotations

import lightning.pytorch as pl

from lit3d.utils.checkpoints import META_KEY


class MetadataCallback(pl.Callback):
    """Stores the task config, data config and W&B run id (plain values) in every checkpoint."""

    def __init__(self, task_cfg: dict, data_cfg: dict, wandb_id: str | None):
        self.meta = {"task": task_cfg, "data": data_cfg, "wandb_id": wandb_id}

    def on_save_checkpoint(self, trainer, pl_module, checkpoint: dict) -> None:
        checkpoint[META_KEY] = self.meta
