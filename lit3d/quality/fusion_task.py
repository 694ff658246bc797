"""The regularised quality fusion (:mod:`lit3d.quality.fusion`) as a LightningModule, so that
``lit3d-train experiment=quality_cpcd2_fusion`` fits the shipped quality model from the data config
and writes it, in the shipped format (:func:`lit3d.quality.shipped.model_document`), as
``quality_model.json`` in the run dir. Nothing is trained by gradient: the fit is closed form.

Before fitting, :class:`FusionFit` (returned by :meth:`QualityFusionTask.configure_callbacks`) takes
the training split (``datamodule.split("train")``: a :class:`~lit3d.features.matrix.FeatureMatrix`
whose ``shapes`` are the groups, e.g. ``data.split.groups=family``) and

- chooses a candidate of :func:`lit3d.quality.fusion_candidates.fusion_candidates` (its model kind,
  feature set and strength) by leave-one-group-out inside the training rows, and fits it on all of them;
- scores the same choice by nested leave-one-group-out over the training groups (each outer fold
  chooses without its held-out group): ``cv/srocc``, ``cv/plcc``, ``cv/krocc`` of the pooled
  out-of-group scores with 95% bootstrap intervals (``evaluation``-free: they are the model card's rows).

Batches are those of ``datamodules.quality`` (``x``: ``(B, F)`` every feature, ``y``: ``(B,)``
distortion in [0, 1]); validation and test log ``<split>/spearman`` and ``<split>/pearson`` of the
model's score with quality over the split. The checkpoint holds the model document
(``checkpoint["quality_fusion"]``).
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import lightning.pytorch as pl
import numpy as np
import torch

from lit3d.features.matrix import FeatureMatrix
from lit3d.quality.correlation import correlation_ci, pearson, spearman
from lit3d.quality.fusion import ChosenFusion, fusion_from_dict, nested_group_out
from lit3d.quality.fusion_candidates import ANCHOR, fusion_candidates
from lit3d.quality.shipped import model_document
from lit3d.utils.io import atomic_write_text

CKPT_KEY = "quality_fusion"
MODEL_FILE = "quality_model.json"


class QualityFusionTask(pl.LightningModule):
    """See the module docstring.

    Args:
        model_name: the model's name in its document.
        feature_sets: ``{set name: [feature, ...]}`` the candidates use (None: the library's
            :data:`~lit3d.quality.fusion_candidates.FEATURE_SETS`).
        anchor: the anchored candidates' anchor feature (None: no anchored candidates).
        bootstrap: resamples of the cross-validated intervals.
        seed: the bootstrap's seed.
    """

    def __init__(self, model_name: str = "quality-fusion", feature_sets: Mapping[str, Sequence[str]] | None = None,
                 anchor: str | None = ANCHOR, bootstrap: int = 2000, seed: int = 0):
        super().__init__()
        self.save_hyperparameters()
        self.automatic_optimization = False
        self.model = None
        self.document: dict | None = None
        self._seen: dict[str, list[np.ndarray]] = {}
        self._columns: torch.Tensor | None = None

    # ------------------------------------------------------------ fit (closed form)
    def candidates(self, names: Sequence[str]) -> dict:
        sets = {k: list(v) for k, v in self.hparams.feature_sets.items()} if self.hparams.feature_sets else None
        out = fusion_candidates(names, sets, self.hparams.anchor)
        if not out:
            raise ValueError(f"the data holds none of the fusion's features (it has {len(names)}, e.g. "
                             f"{list(names)[:3]}): a coloured point-cloud set such as data=cpcd2 has them")
        return out

    def fit_fusion(self, train: FeatureMatrix, *, dataset: str, scaling, feature_options: Mapping,
                   command: str) -> dict:
        """Choose and fit on ``train``, score the choice by nested leave-one-group-out; returns the document."""
        if len(train.shape_names) < 3:
            raise ValueError(f"the fusion's nested protocol needs at least 3 training groups, got "
                             f"{train.shape_names} (data.split.groups=family on CPCD2 gives 3)")
        candidates = self.candidates(train.names)
        chosen = ChosenFusion(candidates).fit(train)
        pred, _ = nested_group_out(train, candidates)
        quality = 1.0 - train.target
        rows = {"cross_validated (nested leave-one-group-out)": {
            f"{c}_all": correlation_ci(-pred, quality, c, n_resamples=int(self.hparams.bootstrap),
                                       seed=int(self.hparams.seed)) for c in ("srocc", "plcc", "krocc")}}
        rows[next(iter(rows))]["n_all"] = len(train)
        trained_on = f"{dataset} ({len(train)} rated pairs; groups {', '.join(train.shape_names)})"
        self.document = model_document(self.hparams.model_name, trained_on, scaling, feature_options, chosen, rows, command)
        self.model = chosen.model
        return self.document

    def configure_callbacks(self) -> list[pl.Callback]:
        return [FusionFit()]

    def configure_optimizers(self):
        return None

    def training_step(self, batch: dict, batch_idx: int) -> None:
        return None  # the fit is closed form (FusionFit); the epoch only carries the loop

    def on_train_epoch_end(self) -> None:
        cv = self.document["cross_validated"] if self.document else {}
        for values in cv.values():
            self.log_dict({f"cv/{c}": float(values[f"{c}_all"][0]) for c in ("srocc", "plcc", "krocc")})

    # ------------------------------------------------------------ validation / test
    def bind_columns(self, data_feature_names: Sequence[str]) -> None:
        pos = {n: i for i, n in enumerate(data_feature_names)}
        missing = [f for f in self.model.inputs if f not in pos]
        if missing:
            raise KeyError(f"the data lacks {len(missing)} feature(s) this model uses, e.g. {missing[:3]}")
        self._columns = torch.tensor([pos[f] for f in self.model.inputs], dtype=torch.long)

    def _collect(self, split: str, batch: dict) -> None:
        x = batch["x"].index_select(1, self._columns.to(batch["x"].device)).double().cpu().numpy()
        score = self.model.quality(x)
        self._seen.setdefault(split, []).append(np.stack([score, 1.0 - batch["y"].double().cpu().numpy()]))

    def _log_split(self, split: str) -> None:
        seen = self._seen.pop(split, [])
        if not seen:
            return
        score, quality = np.concatenate(seen, axis=1)
        self.log_dict({f"{split}/spearman": spearman(score, quality), f"{split}/pearson": pearson(score, quality)})

    def validation_step(self, batch: dict, batch_idx: int) -> None:
        self._collect("val", batch)

    def on_validation_epoch_end(self) -> None:
        self._log_split("val")

    def test_step(self, batch: dict, batch_idx: int) -> None:
        self._collect("test", batch)

    def on_test_epoch_end(self) -> None:
        self._log_split("test")

    # ------------------------------------------------------------ checkpoint
    def on_save_checkpoint(self, checkpoint: dict) -> None:
        checkpoint[CKPT_KEY] = self.document

    def on_load_checkpoint(self, checkpoint: dict) -> None:
        doc = checkpoint.get(CKPT_KEY)
        if not doc:
            raise KeyError("not a quality fusion checkpoint (no 'quality_fusion' entry)")
        self.document = doc
        self.model = fusion_from_dict(doc["fusion"])

    def write_model(self, out_dir: str | Path) -> Path:
        """Write the document as ``out_dir/quality_model.json`` (atomic)."""
        import json

        path = Path(out_dir) / MODEL_FILE
        atomic_write_text(path, json.dumps(self.document, indent=1) + "\n")
        return path

    @staticmethod
    def summary_rows(kwargs: dict) -> list[dict[str, Any]]:
        """``lit3d-summary``: a linear model with no trainable tensors."""
        return [{"component": "fusion (closed form)", "params": 0, "input": "(1, F)", "output": "(1,)"}]


class FusionFit(pl.Callback):
    """Fits the task's fusion on the training split at ``setup("fit")`` (needs ``datamodules.quality``), binds the
    data's columns at every stage, and writes ``quality_model.json`` into the trainer's root dir when fitting ends."""

    def setup(self, trainer: pl.Trainer, pl_module: QualityFusionTask, stage: str) -> None:
        dm = trainer.datamodule
        if dm is None:
            raise RuntimeError("QualityFusionTask needs a datamodule (datamodules.quality.QualityDataModule)")
        if pl_module.model is None:
            if stage != "fit":
                raise RuntimeError("QualityFusionTask has no fitted model: fit it or load a checkpoint")
            hp = dm.hparams
            command = (f"lit3d-train experiment=quality_cpcd2_fusion data.root={hp.get('root')}"
                       if dm.name == "cpcd2" else f"lit3d-train task=quality_fusion data={dm.name}")
            pl_module.fit_fusion(dm.split("train"), dataset=dm.name, scaling=dm.scaling,
                                 feature_options={k: v for k, v in dm.feature_settings.options.items()
                                                  if k != "cache_dir"},  # where tables are kept, not how made
                                 command=command)
        pl_module.bind_columns(dm.feature_names)

    def on_fit_end(self, trainer: pl.Trainer, pl_module: QualityFusionTask) -> None:
        if trainer.is_global_zero and pl_module.document is not None:
            pl_module.write_model(trainer.default_root_dir)
