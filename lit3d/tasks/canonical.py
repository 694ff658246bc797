"""Canonical form from one depth image (thesis ch. 5) as a LightningModule.

Batches come from ``datamodules.canonical`` (``depth``, ``mask``, ``canon_depth``,
``canon_mask``: ``(B, 1, S, S)`` float32; ``subject_idx`` ``(B,)``). The net maps the posed
depth + mask to the canonical depth + mask; the loss is alpha L_depth + beta L_mask with
alpha/beta set per epoch by the :class:`~lit3d.callbacks.loss_phases.LossPhases` callback
that this module adds itself (``configure_callbacks``), so it is saved in checkpoints and a
resumed run continues in its phase. ``mask_loss``: "mse" (thesis) or "bce" (from logits;
measured here: at demo scale the MSE version collapses to an all-background mask, the BCE
version does not).

A NaN/Inf loss term stops training with the step and the term named
(``on_nonfinite="raise"``) or skips that step (``"skip"``, counted in ``skipped_steps``).

Logged: ``train/loss|depth_loss|mask_loss|alpha|beta``; ``val/`` and ``test/`` ``depth_mse``
(masked depth error, see :func:`lit3d.losses_canonical.per_sample_depth_mse`), ``iou`` (mask
IoU), and the same with suffix ``_input`` for the posed-input baseline (the input taken as
its own canonical form). At test time with at least ``retrieval_min_subjects`` subjects:
``test/retrieval/<source>/<nn|ft|st|e|dcg>`` for source = model, input, target (true
canonical, the ceiling) and chance.

Baselines in the same run:
- ``unet_baseline=True`` trains a plain U-Net (``arch=unet``'s net) beside the main net on the
  same batches with the same loss and the same alpha/beta phases (disjoint parameters in one
  Adam, so it is the same as training it alone); logged as ``*_unet`` and retrieval source
  ``unet``. (``arch=unet`` alone trains the U-Net as the main model instead.)
- ``mesh_baselines`` (e.g. ``[cmds, smacof, gps, posed]``): at test time the full meshes of the
  test shapes (one per unique subject x pose, from ``trainer.datamodule.normalized_mesh``) get
  the non-learned canonical forms of :mod:`lit3d.canonical_baselines` and the same descriptor:
  ``test/retrieval/<method>/...``; ``posed`` = the posed full mesh, no canonicalisation.
"""
from __future__ import annotations

from collections.abc import Sequence

import lightning.pytorch as pl
import numpy as np
import torch
from torchmetrics import MeanMetric

from lit3d.callbacks.loss_phases import THESIS_FRACTIONS, LossPhases
from lit3d.losses_canonical import canonical_loss, composite_depth, per_sample_depth_mse, per_sample_mask_iou
from lit3d.nets.canonical import build_canonical_net, summarize
from lit3d.tasks.nonfinite import guard_step, validate_mode

METRICS = ("depth_mse", "iou", "depth_mse_input", "iou_input")
UNET_METRICS = ("depth_mse_unet", "iou_unet")


class CanonicalTask(pl.LightningModule):
    """Posed depth+mask -> canonical depth+mask (CanonicalNet or a plain U-Net baseline)."""

    def __init__(
        self,
        net: dict | None = None,
        arch: str = "canonical",
        use_lfe: bool = True,
        use_msfe: bool = True,
        lr: float = 1e-3,
        betas: Sequence[float] = (0.9, 0.999),
        use_phases: bool = True,
        phases: Sequence[dict] | None = None,
        phase_unit: str = "fraction",
        alpha: float = 1000.0,
        beta: float = 100.0,
        mask_loss: str = "mse",
        mask_threshold: float = 0.5,
        image_every_n_epochs: int = 1,
        n_panel: int = 4,
        retrieval: dict | None = None,
        retrieval_min_subjects: int = 2,
        chance_trials: int = 100,
        unet_baseline: bool = False,
        mesh_baselines: Sequence[str] | None = None,
        baseline_max_vertices: int = 1000,
        baseline_smacof_eps: float = 1e-4,
        on_nonfinite: str = "raise",
    ):
        super().__init__()
        self.save_hyperparameters()
        validate_mode(on_nonfinite)
        cfg = dict(net or {})
        cfg["kind"] = arch
        if arch == "canonical":
            cfg.update(use_lfe=use_lfe, use_msfe=use_msfe)
        self.net = build_canonical_net(cfg)
        # plain U-Net trained beside the main net on the same data and losses (a baseline)
        self.unet = build_canonical_net({**dict(net or {}), "kind": "unet"}) if unet_baseline else None
        # set by LossPhases each epoch; constant weights when phases are off
        self.loss_alpha, self.loss_beta = float(alpha), float(beta)
        names = METRICS + (UNET_METRICS if unet_baseline else ())
        self.val_metrics = torch.nn.ModuleDict({k: MeanMetric() for k in names})
        self.test_metrics = torch.nn.ModuleDict({k: MeanMetric() for k in names})
        self._test_store: list[dict] = []
        self.retrieval_results: dict = {}
        self.skipped_steps = 0  # training steps skipped for a NaN/Inf loss (on_nonfinite=skip)

    # ------------------------------------------------------------------ model
    def forward(self, depth: torch.Tensor, mask: torch.Tensor):
        """``(B,1,S,S)`` depth, mask -> CanonicalOutput (depth, mask probabilities, mask logits)."""
        return self.net(depth, mask)

    def configure_callbacks(self):
        if not self.hparams.use_phases:
            return []
        return [LossPhases(self.hparams.phases or THESIS_FRACTIONS, unit=self.hparams.phase_unit)]

    def configure_optimizers(self):
        return torch.optim.Adam(self.parameters(), lr=self.hparams.lr, betas=tuple(self.hparams.betas))

    # ------------------------------------------------------------------ training
    def _loss(self, net, batch: dict) -> dict[str, torch.Tensor]:
        out = net(batch["depth"], batch["mask"])
        return canonical_loss(out.depth, out.mask, batch["canon_depth"], batch["canon_mask"],
                              self.loss_alpha, self.loss_beta, self.hparams.mask_loss, out.mask_logits)

    def training_step(self, batch: dict, batch_idx: int) -> torch.Tensor | None:
        losses = self._loss(self.net, batch)
        # the weighted total too: finite terms times a huge alpha/beta can still overflow to Inf
        terms = {"depth": losses["depth"], "mask": losses["mask"], "loss": losses["loss"]}
        lu = self._loss(self.unet, batch) if self.unet is not None else None
        if lu is not None:
            terms.update(unet_depth=lu["depth"], unet_mask=lu["mask"], unet_loss=lu["loss"])
        where = f"step {self.global_step} (epoch {self.current_epoch}, batch {batch_idx})"
        if not guard_step(self, terms, where, self.hparams.on_nonfinite):
            return None  # no backward, no optimizer step
        bs = batch["depth"].shape[0]
        self.log_dict({"train/loss": losses["loss"], "train/depth_loss": losses["depth"],
                       "train/mask_loss": losses["mask"]}, on_step=True, on_epoch=True, batch_size=bs)
        total = losses["loss"]
        if lu is not None:
            self.log("train/unet_loss", lu["loss"], on_step=False, on_epoch=True, batch_size=bs)
            total = total + lu["loss"]
        if not self.hparams.use_phases:
            self.log_dict({"train/alpha": self.loss_alpha, "train/beta": self.loss_beta},
                          on_step=False, on_epoch=True, batch_size=bs)
        return total

    # ------------------------------------------------------------------ evaluation
    def _update(self, metrics: torch.nn.ModuleDict, batch: dict, out, out_unet=None) -> None:
        thr = self.hparams.mask_threshold
        d, m = batch["canon_depth"], batch["canon_mask"]
        vals = {
            "depth_mse": per_sample_depth_mse(out.depth, out.mask, d, m, thr),
            "iou": per_sample_mask_iou(out.mask, m, thr),
            "depth_mse_input": per_sample_depth_mse(batch["depth"], batch["mask"], d, m),
            "iou_input": per_sample_mask_iou(batch["mask"], m),
        }
        if out_unet is not None:
            vals["depth_mse_unet"] = per_sample_depth_mse(out_unet.depth, out_unet.mask, d, m, thr)
            vals["iou_unet"] = per_sample_mask_iou(out_unet.mask, m, thr)
        for k, v in vals.items():
            metrics[k].update(v)

    def validation_step(self, batch: dict, batch_idx: int) -> None:
        out = self(batch["depth"], batch["mask"])
        self._update(self.val_metrics, batch, out, self._unet_out(batch))
        loss = canonical_loss(out.depth, out.mask, batch["canon_depth"], batch["canon_mask"], 1.0, 1.0)
        self.log_dict({"val/depth_loss": loss["depth"], "val/mask_loss": loss["mask"]},
                      on_epoch=True, batch_size=batch["depth"].shape[0])
        if batch_idx == 0 and self.hparams.image_every_n_epochs and \
                self.current_epoch % self.hparams.image_every_n_epochs == 0:
            self._log_panels(batch, out)

    def on_validation_epoch_end(self) -> None:
        for k, m in self.val_metrics.items():
            self.log(f"val/{k}", m.compute(), prog_bar=k in ("depth_mse", "iou"))
            m.reset()

    def _unet_out(self, batch: dict):
        return None if self.unet is None else self.unet(batch["depth"], batch["mask"])

    def on_test_epoch_start(self) -> None:
        self._test_store = []

    def test_step(self, batch: dict, batch_idx: int) -> None:
        out = self(batch["depth"], batch["mask"])
        out_u = self._unet_out(batch)
        self._update(self.test_metrics, batch, out, out_u)
        extra = {}
        if out_u is not None:
            extra = {"unet_depth": out_u.depth.detach().float().cpu(), "unet_mask": out_u.mask.detach().float().cpu()}
        self._test_store.append({**extra,
            "pred_depth": out.depth.detach().float().cpu(), "pred_mask": out.mask.detach().float().cpu(),
            "depth": batch["depth"].cpu(), "mask": batch["mask"].cpu(),
            "canon_depth": batch["canon_depth"].cpu(), "canon_mask": batch["canon_mask"].cpu(),
            "subject_idx": torch.as_tensor(batch["subject_idx"]).cpu(),
            "pose": torch.as_tensor(batch["pose"]).cpu(),
        })

    def on_test_epoch_end(self) -> None:
        for k, m in self.test_metrics.items():
            self.log(f"test/{k}", m.compute())
            m.reset()
        if self.hparams.retrieval is None or not self._test_store:
            return
        store = {k: torch.cat([s[k] for s in self._test_store]) for k in self._test_store[0]}
        if self.trainer is not None and self.trainer.world_size > 1:  # pragma: no cover - DDP only
            store = {k: self.all_gather(v.to(self.device)).flatten(0, 1).cpu() for k, v in store.items()}
        labels = store["subject_idx"].numpy()
        counts = np.bincount(labels)
        if (counts >= 2).sum() < self.hparams.retrieval_min_subjects:
            self.print(f"retrieval skipped: fewer than {self.hparams.retrieval_min_subjects} test subjects "
                       "with 2+ items")
            return
        self.retrieval_results = self.retrieval_table(store, labels)
        self.retrieval_results.update(self.mesh_baseline_table(store))
        for source, scores in self.retrieval_results.items():
            for k in ("nn", "ft", "st", "e", "dcg"):
                self.log(f"test/retrieval/{source}/{k}", float(scores[k]), rank_zero_only=True)
            if "seconds" in scores:
                self.log(f"test/retrieval/{source}/seconds", float(scores["seconds"]), rank_zero_only=True)

    def retrieval_table(self, store: dict, labels: np.ndarray) -> dict[str, dict]:
        """Retrieval scores of the predicted canonical forms, the posed inputs and the true canonical
        forms (each depth image back-projected to a surface, then the CM-BOF-style descriptor)."""
        from lit3d.metrics.retrieval import chance_scores, retrieval_scores
        from lit3d.retrieval.descriptor import DescriptorConfig, distance_matrix_from_depths

        cfg = DescriptorConfig(**(self.hparams.retrieval or {}))
        thr = self.hparams.mask_threshold
        sources = {
            "model": (store["pred_depth"], (store["pred_mask"] >= thr).float()),
            "input": (store["depth"], store["mask"]),
            "target": (store["canon_depth"], store["canon_mask"]),
        }
        if "unet_depth" in store:
            sources["unet"] = (store["unet_depth"], (store["unet_mask"] >= thr).float())
        out = {}
        for name, (d, m) in sources.items():
            dist = distance_matrix_from_depths(composite_depth(d, m)[:, 0].numpy(), m[:, 0].numpy(), cfg)
            out[name] = retrieval_scores(dist, labels)
        out["chance"] = chance_scores(labels, self.hparams.chance_trials, seed=0)
        return out

    def mesh_baseline_table(self, store: dict) -> dict[str, dict]:
        """Non-learned canonical forms (``mesh_baselines``) of the full test meshes, one per unique
        (subject, pose) of the test items, through the same descriptor (empty when off, or when the
        datamodule cannot give meshes)."""
        methods = list(self.hparams.mesh_baselines or [])
        dm = getattr(self.trainer, "datamodule", None) if self._trainer is not None else None
        if not methods or dm is None or not hasattr(dm, "normalized_mesh"):
            if methods:
                self.print("mesh baselines skipped: the datamodule has no normalized_mesh()")
            return {}
        import time

        from lit3d.canonical_baselines import baseline_retrieval
        from lit3d.retrieval.descriptor import DescriptorConfig

        names = {i: s for s, i in dm.subject_index.items()}
        keys = sorted({(int(s), int(p)) for s, p in zip(store["subject_idx"], store["pose"])})
        t0 = time.perf_counter()
        meshes = [dm.normalized_mesh(names[s], p) for s, p in keys]
        out = baseline_retrieval(meshes, [s for s, _ in keys], methods, DescriptorConfig(**(self.hparams.retrieval or {})),
                                 self.hparams.baseline_max_vertices, eps=self.hparams.baseline_smacof_eps)
        self.print(f"mesh baselines {methods} on {len(keys)} test shapes: {time.perf_counter() - t0:.0f}s")
        return out

    # ------------------------------------------------------------------ images
    def panel(self, batch: dict, out, n: int | None = None, out_unet=None) -> np.ndarray:
        """uint8 image: rows of input | predicted | target depth | |error| (| U-Net prediction when
        ``out_unet`` is given), one row per sample."""
        n = min(n or self.hparams.n_panel, batch["depth"].shape[0])
        thr = self.hparams.mask_threshold
        rows = []
        for i in range(n):
            pred = composite_depth(out.depth[i, 0], out.mask[i, 0], thr).detach().float().cpu()
            tgt = batch["canon_depth"][i, 0].cpu()
            err = (pred - tgt).abs()
            tiles = [batch["depth"][i, 0].cpu(), pred, tgt, err]
            if out_unet is not None:
                tiles.append(composite_depth(out_unet.depth[i, 0], out_unet.mask[i, 0], thr).detach().float().cpu())
            rows.append(torch.cat([torch.nn.functional.pad(t, (1, 1, 1, 1), value=0.3) for t in tiles], 1))
        return (torch.cat(rows, 0).clamp(0, 1).numpy() * 255).astype(np.uint8)

    def _log_panels(self, batch: dict, out) -> None:
        loggers = [lg for lg in self.loggers if type(lg).__name__ == "WandbLogger"]
        if not loggers or self.trainer.sanity_checking:
            return
        image = self.panel(batch, out)
        for lg in loggers:
            lg.log_image(key="val/panels", images=[image], caption=["input | predicted | true canonical | error"],
                         step=self.global_step)

    # ------------------------------------------------------------------ state
    def on_save_checkpoint(self, checkpoint: dict) -> None:
        checkpoint["skipped_steps"] = self.skipped_steps

    def on_load_checkpoint(self, checkpoint: dict) -> None:
        self.skipped_steps = int(checkpoint.get("skipped_steps", 0))

    # ------------------------------------------------------------------ summary
    @staticmethod
    def summary_rows(kwargs: dict) -> list[dict]:
        """Per-component rows for ``lit3d-summary`` (built on the meta device by the caller)."""
        cfg = dict(kwargs.get("net") or {})
        cfg["kind"] = kwargs.get("arch", "canonical")
        if cfg["kind"] == "canonical":
            cfg.update(use_lfe=kwargs.get("use_lfe", True), use_msfe=kwargs.get("use_msfe", True))
        net = build_canonical_net(cfg)
        rows = summarize(net, int(cfg.get("image_size", 128)))
        return [{"name": r["component"], "params": r["params"], "output_shape": r["output"]} for r in rows]
