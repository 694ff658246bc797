"""3DCascade-GAN shape completion as a LightningModule (manual optimisation, WGAN-GP).

Batches are dicts from ``datamodules.completion``:
    input  (B, 1, r, r, r) float32 {0,1}   partial 2.5D grid (r = out_res / 4)
    target (B, 1, R, R, R) float32 {0,1}   complete solid shape
    label  (B,) int64                      index into ``categories`` or -1 (unseen)
    category list[str]                     category name (seen or unseen)

One training step = ``adversarial.critic_steps`` critic updates, then one generator update
(generator + auxiliary classifier share the generator optimiser). The critic's gradient penalty
runs on every ``adversarial.gp_every``-th critic update, weighted ``gp_every`` times (1 = every update);
``adversarial.critic_concat`` scores real and fake shapes in one critic pass; ``adversarial.gp_precision`` runs the penalty's
critic pass in bf16 (:func:`lit3d.completion.losses.gradient_penalty`); ``compile_step`` runs the critic and
generator objectives through ``torch.compile`` (:mod:`lit3d.completion.compiled_step`). The parts of the step
(:meth:`CompletionTask.critic_objective`, :meth:`CompletionTask.generator_objective`) are what
:mod:`lit3d.completion.step_cost` counts.

Buffers saved in checkpoints (what evaluation needs, so a loaded checkpoint evaluates as it was):
    threshold, prior_threshold  () float32   IoU thresholds chosen on validation (model, prior)
    prior        (1, 1, R, R, R) float32     per-voxel mean of the first ``prior_samples`` training
                                             targets (index order), computed once at fit start
    prior_items  () int64                    training items averaged into ``prior``; 0 = not computed

The test's surface metrics (Chamfer-L1, F-score, normal consistency) are an evaluation setting
(``evaluation.surface``), not the module's: :func:`lit3d.completion.evaluator.prepare` sets them up
before the test (:meth:`CompletionTask.use_surface_metrics`).
"""
from __future__ import annotations

import logging
from collections.abc import Sequence

import lightning.pytorch as pl
import torch
import torch.nn.functional as F

from lit3d.completion.checkpoint_upgrade import EVALUATION_LEGACY
from lit3d.completion.compiled_step import CompiledStep
from lit3d.completion.losses import resolve_loss_scale
from lit3d.completion.objectives import CompletionObjectives
from lit3d.metrics.voxel import VoxelSweepMetrics, best_threshold, default_thresholds
from lit3d.completion.nets import build_completion_nets, validate_net_config
from lit3d.completion.paired import PairedSamples, extrude_silhouette
from lit3d.completion.previews import log_validation_previews
from lit3d.completion.prior import OccupancyPrior
from lit3d.completion.settings import AdversarialSettings, LossWeights, OptimizerSettings, PanelSettings, parse
from lit3d.completion.split_metrics import split_values, threshold_index
from lit3d.completion.summary import summarize_completion
from lit3d.completion.surface_eval import SurfaceTestMetrics
from lit3d.metrics.gathered import compute_if_updated
from lit3d.callbacks.nonfinite import NonFiniteLossError, guard_step, validate_mode  # noqa: F401 (re-exported)
from lit3d.utils.data_hooks import HasLabelCategories
from lit3d.utils.shapenet_categories import SEEN_CATEGORIES, select_seen_categories, select_unseen_categories

log = logging.getLogger("lit3d.completion")

# the test splits as the metrics name them: datamodules.completion.voxel_cache.TEST_SPLITS without "test_"
TEST_SPLIT_KEYS = ("same", "cross", "unseen", "unseen_cross")
# predictions: the model, the partial input upsampled, the per-voxel training prior
PREDICTION_SOURCES = ("model", "input", "prior", "extrusion")


def split_key(name: str) -> str:
    """'test_same' / 'same' -> 'same'."""
    return name.removeprefix("test_")


class CompletionTask(CompletionObjectives, pl.LightningModule):
    """Cascade generator + critic (+ classifier) trained with WGAN-GP and weighted BCE."""

    evaluation_legacy = EVALUATION_LEGACY  # read by lit3d-eval for checkpoints saved before the evaluation node

    # lit3d-eval runs validation first: the IoU threshold is chosen there
    validate_before_test = True

    def __init__(
        self,
        nets: dict,
        optimizer: dict | None = None,
        loss: dict | None = None,
        adversarial: dict | None = None,
        panels: dict | None = None,
        compile_step: bool = False,
        categories: Sequence[str] | None = None,
        unseen_categories: Sequence[str] | None = None,
        prior_samples: int = 256,
        channels_last: bool = False,
        on_nonfinite: str = "raise",
    ):
        """``nets``: the nets' sizes (:func:`lit3d.completion.nets.validate_net_config`); ``optimizer``, ``loss``,
        ``adversarial``, ``panels``: the nodes of :mod:`lit3d.completion.settings` (None: the defaults).
        A checkpoint's hyper-parameters of the flat layout of old (and its evaluation settings, ``surface``):
        :func:`lit3d.completion.checkpoint_upgrade.upgrade_hparams`."""
        super().__init__()
        self.save_hyperparameters()
        validate_mode(on_nonfinite)
        self.optimizer_settings = parse(OptimizerSettings, optimizer, "optimizer")
        self.loss_weights = parse(LossWeights, loss, "loss")
        self.adversarial = parse(AdversarialSettings, adversarial, "adversarial")
        self.panels = parse(PanelSettings, panels, "panels")
        self.automatic_optimization = False
        nets = dict(nets)
        if nets.pop("preset", None) is not None:  # checkpoints written before that change name one beside every size
            log.info("task.nets.preset is ignored: the sizes come from the config alone")
        nets.setdefault("selector_norm", False)  # checkpoints written before that change have none
        self.net_cfg = validate_net_config(nets)
        if self.net_cfg["classifier"] and self.net_cfg["n_classes"] < len(SEEN_CATEGORIES):
            raise ValueError(f"task.nets.n_classes={self.net_cfg['n_classes']}: class labels index the "
                             f"{len(SEEN_CATEGORIES)} seen categories {list(SEEN_CATEGORIES)} (then any of your own)")
        built = build_completion_nets(self.net_cfg)
        self.generator = built["generator"]
        self.critic = built["critic"] if self.adversarial.use else None
        self.classifier = built.get("classifier")
        seen, unseen = select_seen_categories(categories), select_unseen_categories(unseen_categories)
        self.eval_categories = list(seen) + [c for c in unseen if c not in seen]
        self.cat_index = {c: i for i, c in enumerate(self.eval_categories)}
        thresholds = default_thresholds()
        self.register_buffer("thresholds", thresholds.float(), persistent=False)
        self._metric_modules()
        # chosen on validation, applied to test; saved in checkpoints
        self.register_buffer("threshold", torch.tensor(0.5))
        self.register_buffer("prior_threshold", torch.tensor(0.5))
        res = int(self.net_cfg["out_res"])
        self.register_buffer("prior", torch.full((1, 1, res, res, res), 0.5))
        self.register_buffer("prior_items", torch.tensor(0))
        self.test_samples = PairedSamples()
        self.test_surface: SurfaceTestMetrics | None = None  # set before the test: use_surface_metrics
        self.generator_steps = 0
        self.critic_updates = 0  # counts the critic updates (the lazy gradient penalty's schedule)
        self.skipped_steps = 0
        self._compiled: CompiledStep | None = None  # task.compile_step: built on the first training step (its device)
        self.loss_scale = resolve_loss_scale(self.optimizer_settings.loss_scale, res)

    def _metric_modules(self) -> None:
        """Validation and test metrics per category of ``eval_categories`` (states not saved in checkpoints)."""
        thresholds = self.thresholds
        self.val_metrics = torch.nn.ModuleDict(
            {s: VoxelSweepMetrics(self.eval_categories, thresholds) for s in PREDICTION_SOURCES})
        self.test_metrics = torch.nn.ModuleDict(
            {f"{sp}_{s}": VoxelSweepMetrics(self.eval_categories, thresholds)
             for sp in TEST_SPLIT_KEYS for s in PREDICTION_SOURCES}
        )

    def setup(self, stage: str | None = None) -> None:
        """The data's categories of your own (a mesh folder's user categories, ``user_categories`` and
        ``label_categories`` of the DataModule) join the metrics; the classifier must have one class per
        label category (one clear error naming ``task.nets.n_classes`` otherwise)."""
        dm = getattr(self._trainer, "datamodule", None) if self._trainer is not None else None
        labels = list((dm.label_categories if isinstance(dm, HasLabelCategories) else None) or SEEN_CATEGORIES)
        if self.classifier is not None and len(labels) != self.net_cfg["n_classes"]:
            raise ValueError(f"task.nets.n_classes={self.net_cfg['n_classes']}, but the data's class labels are "
                             f"{len(labels)} categories ({', '.join(labels)}): set task.nets.n_classes={len(labels)} "
                             "or task.nets.classifier=false")
        extra = [c for c in (dm.user_categories if isinstance(dm, HasLabelCategories) else ()) if c not in self.cat_index]
        if extra:
            self.eval_categories += extra
            self.cat_index = {c: i for i, c in enumerate(self.eval_categories)}
            self._metric_modules()
            if self.test_surface is not None:
                self.use_surface_metrics(self._surface_settings)

    def use_surface_metrics(self, surface: dict | None) -> None:
        """The test's surface metrics with sizes ``surface`` (``points``, ``fscore_at``, ``seed``: the
        evaluation setting ``evaluation.surface``, set by :func:`lit3d.completion.evaluator.prepare`);
        None = off. Their states are not saved in checkpoints."""
        self._surface_settings = surface
        self.test_surface = (SurfaceTestMetrics(TEST_SPLIT_KEYS, PREDICTION_SOURCES, self.eval_categories, **surface)
                             if surface else None)

    # ------------------------------------------------------------------ helpers
    def forward(self, partial: torch.Tensor) -> torch.Tensor:
        """(B, 1, r, r, r) partial grid -> (B, 1, R, R, R) occupancy probabilities."""
        return torch.sigmoid(self.generator(self._fmt(partial)).logits.float())

    def _fmt(self, x: torch.Tensor) -> torch.Tensor:
        return x.contiguous(memory_format=torch.channels_last_3d) if self.hparams.channels_last else x

    def _categories(self, batch: dict) -> torch.Tensor:
        return torch.tensor([self.cat_index.get(c, -1) for c in batch["category"]], device=self.device)

    @staticmethod
    def upsample_input(partial: torch.Tensor, size: int) -> torch.Tensor:
        """Nearest upsampling of the partial grid: the input-as-prediction baseline."""
        return F.interpolate(partial.float(), size=(size,) * 3, mode="nearest")

    def _check_finite(self, **losses: torch.Tensor) -> bool:
        """False (skip, counted) or raise when a loss is NaN/Inf, naming the step and the term."""
        where = f"generator step {self.generator_steps} (epoch {self.current_epoch})"
        return guard_step(self, losses, where, self.hparams.on_nonfinite)

    # ------------------------------------------------------------------ training
    def configure_optimizers(self):
        hp = self.optimizer_settings
        g_params = list(self.generator.parameters())
        if self.classifier is not None:
            g_params += list(self.classifier.parameters())
        # Adam(scale * g, eps) == Adam(g, eps / scale) exactly: the loss scale is applied as the
        # generator's eps (no overflow risk under 16-mixed, logged losses stay per-voxel means)
        opt_g = torch.optim.Adam(g_params, lr=hp.lr_g, betas=tuple(hp.betas), eps=hp.eps / self.loss_scale)
        if self.critic is None:
            return opt_g
        opt_d = torch.optim.Adam(self.critic.parameters(), lr=hp.lr_d, betas=tuple(hp.betas), eps=hp.eps)
        return [opt_g, opt_d]

    def health_groups(self) -> dict[str, list[torch.nn.Parameter]]:
        """Named parameter groups watched by :class:`lit3d.callbacks.health.TrainingHealth` and
        ``studies/completion/latent_gradients.py``: per generator stage its encoder convs, latent FCs
        (``fc_enc`` + ``fc_dec``), selector weight net and decoder (+ up-sampling, attention);
        then the critic and the classifier. Every trainable parameter is in exactly one group."""
        groups: dict[str, list[torch.nn.Parameter]] = {}
        for s, stage in enumerate(self.generator.stages, start=1):
            latent = list(stage.fc_enc.parameters()) + list(stage.fc_dec.parameters())
            selector = list(stage.selector.parameters()) if stage.selector is not None else []
            taken = {id(p) for p in latent + selector + list(stage.encoder.parameters())}
            groups[f"stage {s} encoder"] = list(stage.encoder.parameters())
            groups[f"stage {s} latent fc"] = latent
            if selector:
                groups[f"stage {s} selector"] = selector
            groups[f"stage {s} decoder"] = [p for p in stage.parameters() if id(p) not in taken]
        for name in ("critic", "classifier"):
            net = getattr(self, name)
            if net is not None:
                groups[name] = list(net.parameters())
        return groups

    def _optimizers(self):
        opts = self.optimizers()
        return (opts[0], opts[1]) if isinstance(opts, list) else (opts, None)

    def _objective(self, name: str):
        """``self.<name>`` (``critic_objective``, ``generator_objective``), through torch.compile with ``compile_step``."""
        if not self.hparams.compile_step:
            return getattr(self, name)
        if self._compiled is None:
            self._compiled = CompiledStep(self)
        return lambda *args: self._compiled(name, *args)

    def training_step(self, batch: dict, batch_idx: int) -> None:
        adv = self.adversarial
        critic_objective, generator_objective = self._objective("critic_objective"), self._objective("generator_objective")
        x, y = self._fmt(batch["input"]), self._fmt(batch["target"])
        opt_g, opt_d = self._optimizers()
        if self.current_epoch < adv.start_epoch:
            opt_d = None  # warm-up: reconstruction (+ classifier) only
        logs: dict[str, torch.Tensor] = {}
        if opt_d is not None:
            for _ in range(adv.critic_steps):
                with self.toggled_optimizer(opt_d):
                    loss_d, critic_logs = critic_objective(x, y, self.critic_updates % adv.gp_every == 0)
                    if self._check_finite(critic=loss_d):
                        opt_d.zero_grad(set_to_none=True)
                        self.manual_backward(loss_d)
                        opt_d.step()
                self.critic_updates += 1
                logs.update(critic_logs)
        with self.toggled_optimizer(opt_g):
            loss_g, terms, out = generator_objective(x, y, batch["label"], opt_d is not None)
            if self._check_finite(generator=loss_g, **terms):
                opt_g.zero_grad(set_to_none=True)
                self.manual_backward(loss_g)
                opt_g.step()
        self.generator_steps += 1
        logs.update(terms)
        logs.update({"loss_g": loss_g, "keep_fraction": out.keep_fraction})
        self.log_dict({f"train/{k}": v.detach().float() for k, v in logs.items()},
                      prog_bar=False, on_step=True, on_epoch=True, batch_size=x.shape[0])
        self.log("train/generator_steps", float(self.generator_steps), on_step=True, on_epoch=False)

    # ------------------------------------------------------------------ prior
    def configure_callbacks(self):
        """The per-voxel prior comes from the training data through a callback
        (:class:`~lit3d.completion.prior.OccupancyPrior`): the module only holds it."""
        return [OccupancyPrior(self.hparams.prior_samples)]

    def set_prior(self, prior: torch.Tensor | None, n_items: int) -> None:
        """Keep ``prior`` ((1, 1, R, R, R) float32 in [0, 1], the mean of ``n_items`` training targets);
        None: no training data, the prior baseline predicts 0.5 everywhere."""
        if prior is None:
            log.warning("no training data: the prior baseline predicts 0.5 everywhere")
            self.prior.fill_(0.5)
        else:
            self.prior.copy_(prior)
        self.prior_items.fill_(int(n_items))

    def _predictions(self, batch: dict) -> dict[str, torch.Tensor]:
        x, y = batch["input"], batch["target"]
        size = y.shape[-1]
        return {
            "model": self(x),
            "input": self.upsample_input(x, size),
            "prior": self.prior.expand(y.shape[0], -1, -1, -1, -1),
            "extrusion": extrude_silhouette(x, size),
        }

    # ------------------------------------------------------------------ validation
    def validation_step(self, batch: dict, batch_idx: int) -> None:
        cats = self._categories(batch)
        preds = self._predictions(batch)
        for src, p in preds.items():
            self.val_metrics[src].update(p, batch["target"], cats)
        if batch_idx == 0:
            log_validation_previews(self, batch)  # panels and meshes to W&B / TensorBoard when due

    def on_validation_epoch_end(self) -> None:
        # updated together; skipped alike on every process when none saw a batch (an empty val split)
        model, prior, inp = (compute_if_updated(self.val_metrics[s]) for s in ("model", "prior", "input"))
        if model is None:
            return
        t, iou = best_threshold(model["iou"], self.thresholds)
        tp, iou_p = best_threshold(prior["iou"], self.thresholds)
        self.threshold.fill_(t)
        self.prior_threshold.fill_(tp)
        self.log_dict({
            "val/iou": iou, "val/threshold": t, "val/ce": float(model["ce"]),
            "val/iou_input": float(inp["iou"][0]), "val/iou_prior": iou_p,
            "val/iou_at_0.5": float(model["iou"][threshold_index(self.thresholds, 0.5)]),
        }, sync_dist=False)
        for m in self.val_metrics.values():
            m.reset()

    def _source_thresholds(self) -> dict[str, float]:  # model and prior: chosen on validation
        return {"model": float(self.threshold), "prior": float(self.prior_threshold), "input": 0.5, "extrusion": 0.5}

    # ------------------------------------------------------------------ test
    def _split_name(self, dataloader_idx: int) -> str:
        dm = getattr(self.trainer, "datamodule", None)
        names = list(getattr(dm, "test_split_names", TEST_SPLIT_KEYS))
        return split_key(names[dataloader_idx]) if dataloader_idx < len(names) else TEST_SPLIT_KEYS[dataloader_idx]

    def test_step(self, batch: dict, batch_idx: int, dataloader_idx: int = 0) -> None:
        split = self._split_name(dataloader_idx)
        cats = self._categories(batch)
        preds = self._predictions(batch)
        for src, p in preds.items():
            self.test_metrics[f"{split}_{src}"].update(p, batch["target"], cats)
        self.test_samples.update(TEST_SPLIT_KEYS.index(split), cats, preds, batch["target"], self._source_thresholds())
        if self.test_surface is not None:
            self.test_surface.update(split, preds, batch["target"], cats, self._source_thresholds())

    def on_test_epoch_end(self) -> None:
        out: dict[str, float] = {"test/threshold": float(self.threshold)}
        out.update(self.test_samples.summary(TEST_SPLIT_KEYS, self.eval_categories))
        self.test_samples.reset()
        out.update(split_values(self.test_metrics, TEST_SPLIT_KEYS, PREDICTION_SOURCES, self._source_thresholds(),
                                self.thresholds, self.eval_categories))
        out.update(self.test_surface.values() if self.test_surface is not None else {})
        self.log_dict(out, sync_dist=False)

    # ------------------------------------------------------------------ state
    def on_save_checkpoint(self, checkpoint: dict) -> None:
        checkpoint["generator_steps"] = self.generator_steps
        checkpoint["critic_updates"] = self.critic_updates
        checkpoint["skipped_steps"] = self.skipped_steps

    def on_load_checkpoint(self, checkpoint: dict) -> None:
        state = checkpoint.get("state_dict")
        if state is not None and "prior" not in state:
            log.info("checkpoint without the occupancy prior (saved before it was kept): "
                     "it is computed from the training data before evaluation")
            state["prior"] = torch.full_like(self.prior, 0.5)
            state["prior_items"] = torch.zeros_like(self.prior_items)
        self.generator_steps = int(checkpoint.get("generator_steps", 0))
        self.critic_updates = int(checkpoint.get("critic_updates", 0))
        self.skipped_steps = int(checkpoint.get("skipped_steps", 0))

    def adapt_data_config(self, data_cfg: dict) -> dict:
        """Make a data config deliver grids at this checkpoint's resolution."""
        return {**data_cfg, "target_res": int(self.net_cfg["out_res"])}

    # ------------------------------------------------------------------ summary
    @staticmethod
    def summary_rows(kwargs: dict) -> list[dict]:
        """Per-component rows for ``lit3d-summary`` (meta device, nothing allocated)."""
        return summarize_completion(kwargs["nets"])


