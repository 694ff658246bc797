"""Feature selection and data binding of the quality task, as a Lightning callback.

:class:`FeatureSelection` is returned by ``QualityTask.configure_callbacks``, so it runs in every
entry point (``lit3d-train``, ``lit3d-eval``, a plain ``Trainer.fit``). Why a callback and not the
module's ``setup()``: selecting features means training many candidate MLPs on the training
split (Algorithm 4.1), which is data work, not wiring; Lightning calls a callback's ``setup``
after the datamodule's own ``setup`` (Lightning calls that, never the module) and before
``configure_optimizers``, the one moment where the training split is there and the network
is not yet needed. Selection is deterministic (``TrainConfig.seed``), so every DDP rank selects
the same features.

At ``setup(stage)`` it

- (fit, no network yet) selects the features on ``datamodule.split("train")``
  (:func:`lit3d.quality.task_methods.select_features`) and has the task build its MLP for them;
- hands the task the data's column order and shape names (``QualityTask.bind_data``) and the
  dataset name, target scaling and feature options the checkpoint records.
"""
from __future__ import annotations

import lightning.pytorch as pl

from lit3d.quality.task_methods import select_features


class FeatureSelection(pl.Callback):
    """See the module docstring. Needs ``trainer.datamodule`` (``datamodules.quality.QualityDataModule``)."""

    def setup(self, trainer: pl.Trainer, pl_module: pl.LightningModule, stage: str) -> None:
        dm = trainer.datamodule
        if dm is None:
            raise RuntimeError("QualityTask needs a datamodule (datamodules.quality.QualityDataModule)")
        if pl_module.net is None:
            if stage != "fit":
                raise RuntimeError("QualityTask has no trained network: fit it or load a checkpoint")
            features, sfs_info = select_features(pl_module.hparams, dm.split("train"), pl_module.train_config())
            pl_module.use_features(features, sfs_info)
        pl_module.dataset_name = dm.name
        if pl_module.feature_options is None:
            pl_module.feature_options = dict(dm.feature_settings.options)
        if pl_module.scaling is None:
            pl_module.scaling = dm.scaling
        pl_module.bind_data(dm.feature_names, dm.shape_names)
