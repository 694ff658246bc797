"""What ``lit3d-eval`` needs, stored in every checkpoint under ``checkpoint["lit3d"]``."""
from __future__ import annotations

import lightning.pytorch as pl

from lit3d.utils.checkpoints import META_KEY
from lit3d.utils.provenance import code_provenance, data_provenance


class MetadataCallback(pl.Callback):
    """Stores the task config, data config, evaluation settings, W&B run id and the run's provenance
    (plain values) in every checkpoint: ``{"task", "data", "evaluation", "wandb_id", "provenance"}``,
    ``evaluation`` the config's resolved ``evaluation`` node (what ``lit3d-eval`` of the checkpoint
    evaluates with, :mod:`lit3d.runtime.eval_settings`; left out when None), ``provenance`` as
    :func:`lit3d.utils.provenance.provenance` (lit3d version, git commit, the data's manifest hash)."""

    def __init__(self, task_cfg: dict, data_cfg: dict, wandb_id: str | None, evaluation: dict | None = None):
        self.meta = {"task": task_cfg, "data": data_cfg, "wandb_id": wandb_id}
        if evaluation is not None:
            self.meta["evaluation"] = evaluation
        self.code = code_provenance()  # once: git runs in a subprocess

    def on_save_checkpoint(self, trainer, pl_module, checkpoint: dict) -> None:
        """``trainer`` may be None (a checkpoint written without training): no data provenance then."""
        datamodule = getattr(trainer, "datamodule", None)
        checkpoint[META_KEY] = {**self.meta, "provenance": {**self.code, **data_provenance(datamodule)}}
