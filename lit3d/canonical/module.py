"""Canonical form from one depth image (thesis ch. 5) as a LightningModule.

Batches come from ``datamodules.canonical`` (``depth``, ``mask``, ``canon_depth``,
``canon_mask``: ``(B, 1, S, S)`` float32; ``subject_idx`` ``(B,)``). The net maps the posed
depth + mask to the canonical depth + mask; the loss is alpha L_depth + beta L_mask with
alpha/beta set per epoch by the :class:`~lit3d.canonical.loss_phases.LossPhases` callback
that this module adds itself (``configure_callbacks``), so it is saved in checkpoints and a
resumed run continues in its phase. ``mask_loss``: "mse" (thesis) or "bce" (from logits;
measured here: at demo scale the MSE version collapses to an all-background mask, the BCE
version does not).

A NaN/Inf loss term stops training with the step and the term named
(``on_nonfinite="raise"``) or skips that step (``"skip"``, counted in ``skipped_steps``).

The settings are config nodes (:mod:`lit3d.canonical.settings`): ``net`` (the net's sizes and switches,
:func:`~lit3d.canonical.factory.build_canonical_net`), ``optimizer``, ``phases`` and the auxiliary objectives,
each off at weight 0:

- ``identity`` adds a subject classifier (one linear layer, ``identity.classes`` outputs) on the MSFE's fused
  latent and its cross-entropy, times ``identity.weight``: the latent names the subject too;
- ``warp``: with ``net.head.kind="warp"`` (:mod:`lit3d.canonical.warp`; it moves the posed pixels instead of
  redrawing them) its terms (:data:`WARP_TERMS`, :mod:`lit3d.canonical.warp_loss`) times their
  ``warp.<term>_weight`` join the loss, the flow and visibility where the batch has flow targets
  (``data.render.flow_targets``).

Options measured and not adopted (the splat head, the warp head's variants, the phenotype and contrastive
objectives, ...) are at the git tag ``parked-canonical-options`` (studies/canonical/LOG.md); checkpoints that
used one are refused by :func:`lit3d.canonical.checkpoint_upgrade.upgrade_checkpoint`.

``arch="recall"`` is the closed-set recall row (:mod:`lit3d.canonical.recall`): a subject classifier
(``identity.classes`` subjects) whose output is the recalled training canonical image; its templates are
filled from the training data at fit start and saved in the checkpoint; its cross-entropy x ``identity.weight`` too.

Checkpoints of the flat layout before these nodes load through
:func:`lit3d.canonical.checkpoint_upgrade.upgrade_checkpoint`.

Logged: ``train/loss|depth_loss|mask_loss|alpha|beta`` (``identity_loss`` with the classifier;
``flow_loss|vis_loss|smooth_loss`` and ``val/flow_epe`` in pixels with the warp head); ``val/`` and ``test/`` ``depth_mse``
(masked depth error, :class:`lit3d.metrics.depth.MaskedDepthMSE`), ``iou`` (mask IoU,
:class:`lit3d.metrics.depth.MaskIoU`), and the same with suffix ``_input`` for the posed-input
baseline (the input taken as its own canonical form); ``val/retrieval_nn|ft`` (and ``_input``): the
validation subjects retrieved by their masks (:func:`validation_retrieval`).

At test time the module also gathers, in :attr:`CanonicalTask.test_outputs` (a DDP-correct
:class:`lit3d.metrics.gathered.GatheredTensors`), every test item's prediction, input, target,
subject and pose; :func:`lit3d.canonical.evaluator.protocol` scores retrieval and the mesh
baselines from it after the test, with settings of its own (the config's ``evaluation`` node:
``retrieval``, ``retrieval_min_subjects``, ``chance_trials``, ``ceiling_jitter_deg``, ``mesh_baselines``,
``baseline_*``), not this module's. The plain U-Net baseline is a run of its own (``arch=unet``, same
data and losses).
"""
from __future__ import annotations

import lightning.pytorch as pl
import torch

from lit3d.callbacks.nonfinite import guard_step, validate_mode
from lit3d.canonical.checkpoint_upgrade import EVALUATION_LEGACY, upgrade_checkpoint
from lit3d.canonical.figures import validation_panel
from lit3d.canonical.loss_phases import THESIS_FRACTIONS, LossPhases
from lit3d.canonical.factory import build_canonical_net, summarize
from lit3d.canonical.recall import RecallTemplates
from lit3d.canonical.settings import IdentityObjective, OptimizerSettings, PanelSettings, PhaseSettings, WarpObjective, parse
from lit3d.canonical.losses import canonical_loss, flow_loss
from lit3d.canonical.warp_loss import flow_targets, warp_terms
from lit3d.metrics.depth import MaskedDepthMSE, MaskIoU
from lit3d.metrics.gathered import GatheredTensors, compute_if_updated
from lit3d.metrics.retrieval import mask_retrieval
from lit3d.utils.checkpoints import load_checkpoint
from lit3d.utils.log_images import log_image, media_loggers

METRICS = ("depth_mse", "iou", "depth_mse_input", "iou_input")
# the warp head's loss terms (flow_weight, vis_weight, smooth_weight)
WARP_TERMS = ("flow", "vis", "smooth")
# per test item, gathered for the evaluator: prediction (depth, mask probability), posed input,
# true canonical form ((N, 1, S, S) float32), subject index, pose and view ((N,) int64)
# "index": the item's place in the test set, so the evaluator sees the items in one order under DDP too
TEST_OUTPUTS = ("pred_depth", "pred_mask", "depth", "mask", "canon_depth", "canon_mask", "subject_idx", "pose", "view",
                "index")

# per validation item: the prediction's mask (at mask_threshold) and the posed input's ((N, 1, S, S) bool), subject
VAL_OUTPUTS = ("pred_mask", "mask", "subject_idx")


def validation_retrieval(gathered: dict[str, torch.Tensor]) -> dict[str, float]:
    """Retrieval of the validation subjects by their masks (distance 1 - mask IoU, classes = subjects:
    :func:`lit3d.metrics.retrieval.mask_retrieval`): ``{"retrieval_nn", "retrieval_ft"}`` of the
    predictions and ``..._input`` of the posed inputs, from :data:`VAL_OUTPUTS` ``(N, 1, S, S)`` masks and
    ``(N,)`` subjects; ``{}`` when no subject has two items. A figure on people never tested, for
    choosing settings that keep the person (the test's descriptor is too slow for every epoch)."""
    labels = gathered["subject_idx"].cpu().numpy()
    if len(labels) == len(set(labels.tolist())):
        return {}
    out = {}
    for key, suffix in (("pred_mask", ""), ("mask", "_input")):
        masks = gathered[key].cpu().numpy()
        scores = mask_retrieval(masks.reshape(len(masks), *masks.shape[-2:]), labels)
        out.update({f"retrieval_nn{suffix}": float(scores["nn"]), f"retrieval_ft{suffix}": float(scores["ft"])})
    return out


class CanonicalTask(pl.LightningModule):
    """Posed depth+mask -> canonical depth+mask (CanonicalNet; a plain U-Net with ``arch="unet"``; the
    closed-set recall net with ``arch="recall"``)."""

    evaluation_legacy = EVALUATION_LEGACY  # read by lit3d-eval for checkpoints saved before the evaluation node

    def __init__(self, net: dict | None = None, arch: str = "canonical", optimizer: dict | None = None,
                 phases: dict | None = None, mask_loss: str = "mse", mask_threshold: float = 0.5,
                 warp: dict | None = None, identity: dict | None = None, panels: dict | None = None,
                 on_nonfinite: str = "raise",
                 init_weights: str | None = None):
        """``net``: the net's config (its parts ``lfe``, ``msfe``, ``reconstruction``, ``head``: :func:`build_canonical_net`);
        ``optimizer``, ``phases``, ``warp``, ``identity``, ``panels``: the nodes of
        :mod:`lit3d.canonical.settings` (None: every default, the objectives off)."""
        super().__init__()
        self.save_hyperparameters()
        validate_mode(on_nonfinite)
        self.optimizer_settings = parse(OptimizerSettings, optimizer, "optimizer")
        self.phases = parse(PhaseSettings, phases, "phases")
        self.warp = parse(WarpObjective, warp, "warp")
        self.identity = parse(IdentityObjective, identity, "identity")
        self.panels = parse(PanelSettings, panels, "panels")
        cfg = dict(net or {})
        cfg["kind"] = arch
        if arch == "recall":  # closed-set recall row: the net is the subject classifier (lit3d.canonical.recall)
            cfg["n_subjects"] = self.identity.classes
        msfe = dict(cfg.get("msfe") or {})
        use_msfe = bool(msfe.get("use", True))
        self.net = build_canonical_net(cfg)
        latent = int(msfe.get("fuser_out", 500))
        self.identity_head = None  # subject classifier on the MSFE latent (identity.weight > 0)
        ident = self.identity
        if ident.weight > 0 and arch != "recall":
            if arch != "canonical" or not use_msfe or ident.classes < 2:
                raise ValueError("task.identity.weight > 0 needs arch=canonical with the MSFE and task.identity.classes "
                                 f">= 2 (the number of training subjects); got arch={arch}, use_msfe={use_msfe}, "
                                 f"classes={ident.classes}")
            self.identity_head = torch.nn.Linear(latent, int(ident.classes))
        # LossPhases sets them each epoch, if on
        self.loss_alpha, self.loss_beta = float(self.phases.alpha), float(self.phases.beta)
        self.val_metrics = self._image_metrics(mask_threshold)
        self.test_metrics = self._image_metrics(mask_threshold)
        self.test_outputs = GatheredTensors(TEST_OUTPUTS)  # read by lit3d.canonical.evaluator.protocol
        self.val_outputs = GatheredTensors(VAL_OUTPUTS)  # the validation retrieval by mask IoU
        self.skipped_steps = 0  # training steps skipped for a NaN/Inf loss (on_nonfinite=skip)

    @staticmethod
    def _image_metrics(threshold: float) -> torch.nn.ModuleDict:
        """The :data:`METRICS`: the prediction binarised at ``threshold``, the posed input at 0.5."""
        return torch.nn.ModuleDict({"depth_mse": MaskedDepthMSE(threshold), "iou": MaskIoU(threshold),
                                    "depth_mse_input": MaskedDepthMSE(), "iou_input": MaskIoU()})

    # ------------------------------------------------------------------ model
    def forward(self, depth: torch.Tensor, mask: torch.Tensor):
        """``(B,1,S,S)`` depth, mask -> CanonicalOutput (depth, mask probabilities, mask logits)."""
        return self.net(depth, mask)

    def load_initial_weights(self, path: str) -> None:
        """Start from the net of another canonical checkpoint ``path`` (pretraining, e.g. on Anny
        bodies): its ``net.*`` weights, every one present with the same shape, else one ValueError
        naming the file and the first mismatch. The optimiser starts afresh."""
        state = upgrade_checkpoint(load_checkpoint(path), str(path)).get("state_dict", {})
        net = {k[len("net."):]: v for k, v in state.items() if k.startswith("net.")}
        own = self.net.state_dict()
        for k, v in own.items():
            if k not in net or tuple(net[k].shape) != tuple(v.shape):
                have = "missing" if k not in net else f"shape {tuple(net[k].shape)}"
                raise ValueError(f"{path}: not a pretrained net for this one (net.{k}: {have}, "
                                 f"expected {tuple(v.shape)}; same task.arch and task.net sizes?)")
        data_made = {k for k in own if k.startswith("template_")}  # recall templates: this run's training data
        self.net.load_state_dict({k: own[k] if k in data_made else net[k] for k in own})

    def on_fit_start(self) -> None:
        """``init_weights``: a fresh fit (not a resume) starts from that checkpoint's net (``arch=recall``:
        its templates come from this run's training data, :class:`~lit3d.canonical.recall.RecallTemplates`)."""
        if self.hparams.init_weights and getattr(self.trainer, "ckpt_path", None) is None:
            self.load_initial_weights(self.hparams.init_weights)

    def configure_callbacks(self):
        """The loss phases (``phases.use``) and, for ``arch=recall``, the templates from the training data."""
        callbacks = [RecallTemplates()] if self.hparams.arch == "recall" else []
        if self.phases.use:
            callbacks.append(LossPhases(list(self.phases.weights or THESIS_FRACTIONS), unit=self.phases.unit))
        return callbacks

    def configure_optimizers(self):
        """Adam at ``optimizer.lr``; ``optimizer.schedule="cosine"``: the rate falls along a half cosine to 0 over
        the run's training steps (updated every step)."""
        o = self.optimizer_settings
        opt = torch.optim.Adam(self.parameters(), lr=o.lr, betas=tuple(o.betas))
        if o.schedule == "constant":
            return opt
        steps = max(int(self.trainer.estimated_stepping_batches), 1)
        sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, T_max=steps)
        return {"optimizer": opt, "lr_scheduler": {"scheduler": sched, "interval": "step"}}

    # ------------------------------------------------------------------ training
    def training_step(self, batch: dict, batch_idx: int) -> torch.Tensor | None:
        out = self.net(batch["depth"], batch["mask"])
        losses = canonical_loss(out.depth, out.mask, batch["canon_depth"], batch["canon_mask"],
                                self.loss_alpha, self.loss_beta, self.hparams.mask_loss, out.mask_logits)
        # the weighted total too: finite terms times a huge alpha/beta can still overflow to Inf
        terms = {"depth": losses["depth"], "mask": losses["mask"], "loss": losses["loss"]}
        if self.identity.weight > 0:  # the MSFE's identity head, or the recall net's own logits
            terms["identity"] = self._identity_loss(out.latent, batch["subject_idx"])
            terms["loss"] = terms["loss"] + self.identity.weight * terms["identity"]
        if out.flow is not None:  # the warp head: each of its terms times its weight
            terms.update(warp := warp_terms(out, batch))
            terms["loss"] = terms["loss"] + sum(getattr(self.warp, f"{k}_weight") * v for k, v in warp.items())
        where = f"step {self.global_step} (epoch {self.current_epoch}, batch {batch_idx})"
        if not guard_step(self, terms, where, self.hparams.on_nonfinite):
            return None  # no backward, no optimizer step
        bs = batch["depth"].shape[0]
        self.log_dict({"train/loss": terms["loss"], "train/depth_loss": losses["depth"],
                       "train/mask_loss": losses["mask"]}, on_step=True, on_epoch=True, batch_size=bs)
        for k in ("identity", *WARP_TERMS):
            if k in terms:
                self.log(f"train/{k}_loss", terms[k], on_step=False, on_epoch=True, batch_size=bs)
        if not self.phases.use:
            self.log_dict({"train/alpha": self.loss_alpha, "train/beta": self.loss_beta},
                          on_step=False, on_epoch=True, batch_size=bs)
        return terms["loss"]

    def _identity_loss(self, latent: torch.Tensor, subject_idx) -> torch.Tensor:
        """Cross-entropy of the subject classifier on the MSFE latent ``(B, fuser_out)`` (``arch=recall``: of
        the recall net's logits ``(B, K)``); ``subject_idx`` ``(B,)`` (the DataModule's subject index).
        ValueError when an index is outside the classifier."""
        target = torch.as_tensor(subject_idx, device=latent.device).long()
        n = self.net.n_subjects if self.identity_head is None else self.identity_head.out_features
        if target.min() < 0 or target.max() >= n:
            raise ValueError(f"subject index {int(target.max())} outside identity.classes={n}: set "
                             "task.identity.classes to the number of subjects of the data")
        logits = latent.float() if self.identity_head is None else self.identity_head(latent.float())
        return torch.nn.functional.cross_entropy(logits, target)

    # ------------------------------------------------------------------ evaluation
    @staticmethod
    def _update(metrics: torch.nn.ModuleDict, batch: dict, out) -> None:
        d, m = batch["canon_depth"], batch["canon_mask"]
        metrics["depth_mse"].update(out.depth, out.mask, d, m)
        metrics["iou"].update(out.mask, m)
        metrics["depth_mse_input"].update(batch["depth"], batch["mask"], d, m)
        metrics["iou_input"].update(batch["mask"], m)

    def validation_step(self, batch: dict, batch_idx: int) -> None:
        out = self(batch["depth"], batch["mask"])
        self._update(self.val_metrics, batch, out)
        self.val_outputs.update(pred_mask=out.mask >= self.hparams.mask_threshold, mask=batch["mask"] > 0.5,
                                subject_idx=torch.as_tensor(batch["subject_idx"], device=self.device))
        loss = canonical_loss(out.depth, out.mask, batch["canon_depth"], batch["canon_mask"], 1.0, 1.0)
        bs = batch["depth"].shape[0]
        self.log_dict({"val/depth_loss": loss["depth"], "val/mask_loss": loss["mask"]}, on_epoch=True, batch_size=bs)
        if out.flow is not None and "has_flow" in batch and bool(batch["has_flow"].any()):
            # end-point error in pixels on the visible pixels of the items with targets
            target, vis, has = flow_targets(out, batch)
            epe = flow_loss(out.flow, target, vis, has) * batch["depth"].shape[-1] / 2
            self.log("val/flow_epe", epe, on_epoch=True, batch_size=bs)
        every = self.panels.every_n_epochs
        if batch_idx == 0 and every and self.current_epoch % every == 0:
            self._log_panels(batch, out)

    def on_validation_epoch_end(self) -> None:
        for k, m in self.val_metrics.items():
            self.log(f"val/{k}", m.compute(), prog_bar=k in ("depth_mse", "iou"))
            m.reset()
        gathered = compute_if_updated(self.val_outputs)
        self.val_outputs.reset()
        if gathered and not self.trainer.sanity_checking:
            self.log_dict({f"val/{k}": v for k, v in validation_retrieval(gathered).items()})

    def on_test_epoch_start(self) -> None:
        self.test_outputs.reset()

    def test_step(self, batch: dict, batch_idx: int) -> None:
        out = self(batch["depth"], batch["mask"])
        self._update(self.test_metrics, batch, out)
        self.test_outputs.update(
            pred_depth=out.depth.float(), pred_mask=out.mask.float(), depth=batch["depth"], mask=batch["mask"],
            canon_depth=batch["canon_depth"], canon_mask=batch["canon_mask"],
            subject_idx=torch.as_tensor(batch["subject_idx"], device=self.device),
            pose=torch.as_tensor(batch["pose"], device=self.device),
            view=torch.as_tensor(batch["view"], device=self.device),
            index=torch.as_tensor(batch["index"], device=self.device))

    def on_test_epoch_end(self) -> None:
        for k, m in self.test_metrics.items():
            self.log(f"test/{k}", m.compute())
            m.reset()

    # ------------------------------------------------------------------ images
    def _log_panels(self, batch: dict, out) -> None:
        loggers = media_loggers(self.loggers)  # W&B and TensorBoard (lit3d.utils.log_images)
        if not loggers or self.trainer.sanity_checking:
            return
        image = validation_panel(batch, out, self.panels.n, self.hparams.mask_threshold)
        log_image(loggers, "val/panels", image, self.global_step, caption="input | predicted | true canonical | error")

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
        net = build_canonical_net(cfg)
        rows = summarize(net, int(cfg.get("image_size", 128)))
        return [{"name": r["component"], "params": r["params"], "output_shape": r["output"]} for r in rows]
