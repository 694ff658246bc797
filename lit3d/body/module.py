"""The body regressor (:class:`lit3d.body_fit.regressor.BodyRegressor`) as a LightningModule: its
loss, optimiser, schedule and logging. Nothing else.

Batches come from :class:`datamodules.body.BodyDataModule`: ``image (B, 2, S, S)``, ``extras (B, 3)``
and the targets ``phenotype (B, 6)``, ``theta (B, D)``, ``rotmat (B, 3, 3)``, ``translation (B, 3)``
(metres, relative to the fit's start centre).

Loss: :func:`lit3d.body_fit.regressor.loss` (phenotype units, radians, rotation-matrix entries and
``w_translation`` x metres, squared). Adam at ``lr``, cosine-decayed to 0 over ``trainer.max_steps``.
Logged: ``train/loss`` and its terms per step; ``val/...`` and ``test/...``: ``loss``, its terms,
``phenotype_mae`` (units), ``theta_mae`` (radians), ``translation_mae_m`` (metres), means over people.

The checkpoint is a product input: ``lit3d-reconstruct --body --body-init CKPT`` reads it
(:func:`lit3d.body_fit.regressor.load_regressor`) from ``hyper_parameters`` (``preprocess``, ``net``)
and the ``net.`` entries of the state dict.
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import lightning.pytorch as pl
import torch

from lit3d.body_fit.regressor import BodyRegressor, Preprocess, Regressor, loss

TERMS = ("phenotype", "theta", "rotmat", "translation")


class BodyRegressorTask(pl.LightningModule):
    """Args:
        preprocess: :class:`~lit3d.body_fit.regressor.Preprocess` fields (crop size, depth unit, ...);
            the data config reads them from here (``data.preprocess: ${task.preprocess}``).
        net: :class:`~lit3d.body_fit.regressor.BodyRegressor` sizes: ``width``, ``hidden``.
        lr: Adam's learning rate at step 0.
        w_translation: weight of the translation term (metres squared).
    """

    def __init__(self, preprocess: Mapping[str, Any] | None = None, net: Mapping[str, Any] | None = None,
                 lr: float = 1e-3, w_translation: float = 100.0):
        super().__init__()
        self.save_hyperparameters()
        self.prep = Preprocess(**dict(preprocess or {}))
        self.net = BodyRegressor(self.prep.size, **dict(net or {}))

    def forward(self, image: torch.Tensor, extras: torch.Tensor) -> dict[str, torch.Tensor]:
        """``(B, 2, S, S)``, ``(B, 3)`` -> :meth:`~lit3d.body_fit.regressor.BodyRegressor.decode`'s dict."""
        return self.net.decode(self.net(image, extras))

    def regressor(self) -> Regressor:
        """This network as the body fit's start (:class:`~lit3d.body_fit.regressor.Regressor`)."""
        return Regressor(self.net, self.prep, "<lit3d.body task>")

    def _loss(self, batch: dict) -> tuple[torch.Tensor, dict[str, float], dict[str, torch.Tensor]]:
        pred = self(batch["image"], batch["extras"])
        total, terms = loss(pred, batch, self.hparams.w_translation)
        return total, terms, pred

    def training_step(self, batch: dict, batch_idx: int) -> torch.Tensor:
        total, terms, _ = self._loss(batch)
        n = batch["image"].shape[0]
        self.log("train/loss", total, prog_bar=True, batch_size=n)
        for k in TERMS:
            self.log(f"train/{k}", terms[k], batch_size=n)
        return total

    def _evaluate(self, batch: dict, stage: str) -> None:
        total, terms, pred = self._loss(batch)
        n = batch["image"].shape[0]
        errors = {"loss": total, **terms,
                  "phenotype_mae": (pred["phenotype"] - batch["phenotype"]).abs().mean(),
                  "theta_mae": (pred["theta"] - batch["theta"]).abs().mean(),
                  "translation_mae_m": (pred["translation"] - batch["translation"]).abs().mean()}
        for k, v in errors.items():
            self.log(f"{stage}/{k}", v, batch_size=n, sync_dist=True, prog_bar=k == "loss" and stage == "val")

    def validation_step(self, batch: dict, batch_idx: int) -> None:
        self._evaluate(batch, "val")

    def test_step(self, batch: dict, batch_idx: int) -> None:
        self._evaluate(batch, "test")

    def configure_optimizers(self):
        opt = torch.optim.Adam(self.net.parameters(), lr=self.hparams.lr)
        steps = self.trainer.max_steps if self.trainer is not None and self.trainer.max_steps > 0 else None
        if steps is None:
            return opt
        sched = torch.optim.lr_scheduler.LambdaLR(opt, lambda s: 0.5 * (1 + math.cos(math.pi * min(s / steps, 1.0))))
        return {"optimizer": opt, "lr_scheduler": {"scheduler": sched, "interval": "step"}}
