"""The losses of a completion training step, as methods of :class:`lit3d.completion.module.CompletionTask`.

Each part of the manual-optimisation step is one method, called by ``training_step`` and by the cost
model (:mod:`lit3d.completion.step_cost` counts them on the meta device, so its count follows this code):

    critic update:    critic_fakes (generator, no graph) -> critic_scores (real + fake) -> critic_penalty
                      (WGAN-GP, on every ``gp_every``-th update), combined by critic_objective
    generator update: generator_objective (generator, BCE, critic's adversarial term, classifier)

The mixin reads ``self.generator``, ``self.critic``, ``self.classifier``, ``self.loss_weights`` (``gamma``, ``alpha``,
``zeta``, ``stage_weight``) and ``self.adversarial`` (``gp_lambda``, ``gp_every``, ``critic_concat``, ``gp_precision``):
:mod:`lit3d.completion.settings`.
Shapes: partial inputs ``x`` ``(B, 1, r, r, r)``, shapes ``(B, 1, R, R, R)``.
"""
from __future__ import annotations

import torch
import torch.nn.functional as F

from lit3d.completion.losses import critic_loss, generator_adv_loss, gradient_penalty, weighted_bce_with_logits


class CompletionObjectives:
    """The critic's and the generator's objectives (a mixin of the LightningModule)."""

    def critic_fakes(self, x: torch.Tensor) -> torch.Tensor:
        """The critic update's fakes: generator probabilities ``(B, 1, R, R, R)`` of partial inputs ``x``
        ``(B, 1, r, r, r)``, without a graph."""
        with torch.no_grad():
            return torch.sigmoid(self.generator(x).logits)

    def critic_scores(self, x: torch.Tensor, real: torch.Tensor, fake: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``(D(real | x), D(fake | x))``, each ``(B,)``, for ``x`` ``(B, 1, r, r, r)`` and shapes ``(B, 1, R, R, R)``.

        ``task.adversarial.critic_concat``: one critic pass over the batch of ``2B`` (real then fake) instead of two
        passes; the same values up to float rounding, as the critic couples no samples (no batch norm;
        its attention is within a sample).
        """
        if not self.adversarial.critic_concat:
            return self.critic(x, real), self.critic(x, fake)
        d = self.critic(torch.cat([x, x]), torch.cat([real, fake]))
        return d[: x.shape[0]], d[x.shape[0]:]

    @torch.compiler.disable  # a double backward: eager under task.compile_step (lit3d.completion.compiled_step)
    def critic_penalty(self, x: torch.Tensor, real: torch.Tensor, fake: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """WGAN-GP penalty of the critic and the mean gradient norm (:func:`lit3d.completion.losses.gradient_penalty`),
        its critic pass in ``task.adversarial.gp_precision`` (fp32 or bf16 autocast; the norm and the penalty in fp32)."""
        return gradient_penalty(self.critic, x, real, fake, precision=self.adversarial.gp_precision)

    def critic_objective(self, x: torch.Tensor, y: torch.Tensor, with_penalty: bool = True) -> tuple[torch.Tensor, dict]:
        """The loss of one critic update and its logged terms.

        ``E[D(fake)] - E[D(real)] + gp_lambda * gp_every * gp`` when ``with_penalty`` (the lazy
        regularisation of StyleGAN2: with ``task.adversarial.gp_every = N`` the penalty is computed on one critic
        update in N and weighted N times, the same penalty on average), else without the penalty.

        Args:
            x: ``(B, 1, r, r, r)`` partial inputs; y: ``(B, 1, R, R, R)`` targets (the real shapes).
        Returns:
            (scalar fp32 loss, ``{"wasserstein": ..., ["gp": ..., "grad_norm": ...]}``).
        """
        hp = self.adversarial
        fake = self.critic_fakes(x)
        d_real, d_fake = self.critic_scores(x, y, fake)
        logs = {"wasserstein": (d_real - d_fake).mean()}
        gp, lam = torch.zeros((), device=d_real.device), 0.0
        if with_penalty:
            gp, grad_norm = self.critic_penalty(x, y, fake)
            lam = hp.gp_lambda * hp.gp_every
            logs.update({"gp": gp, "grad_norm": grad_norm})
        loss_d = critic_loss(d_fake, d_real, gp, lam)
        logs["loss_d"] = loss_d
        return loss_d, logs

    def generator_objective(self, x: torch.Tensor, y: torch.Tensor, labels: torch.Tensor,
                            adversarial: bool = True) -> tuple[torch.Tensor, dict, object]:
        """The loss of one generator update, its terms and the generator output.

        ``gamma * BCE (+ stage_weight * stage BCE) + (1 - gamma) * adversarial + zeta * classifier CE``
        (without the critic: BCE weight 1, no adversarial term).

        Args:
            x: ``(B, 1, r, r, r)`` partial inputs; y: ``(B, 1, R, R, R)`` targets.
            labels: ``(B,)`` int64 seen-category indices, -1 for unseen (no classifier term).
            adversarial: the critic's term on (it is off during the warm-up).
        Returns:
            (scalar fp32 loss, terms, :class:`lit3d.completion.generator.GeneratorOutput`).
        """
        hp = self.loss_weights
        out = self.generator(x)
        probs = torch.sigmoid(out.logits)
        loss_g, terms = self.reconstruction_loss(out, y, hp.gamma if adversarial else 1.0)
        if adversarial:
            terms["adv"] = generator_adv_loss(self.critic(x, probs))
            loss_g = loss_g + (1 - hp.gamma) * terms["adv"]
        if self.classifier is not None:
            seen = labels >= 0
            n_seen = int(seen.sum())
            if n_seen:
                logits = self.classifier(probs if n_seen == len(seen) else probs[seen]).float()
                terms["cls"] = F.cross_entropy(logits, labels[seen].to(logits.device))
                loss_g = loss_g + hp.zeta * terms["cls"]
        return loss_g, terms, out

    def reconstruction_loss(self, out, target: torch.Tensor, weight: float = 1.0) -> tuple[torch.Tensor, dict]:
        """``weight * BCE(final) + stage_weight * BCE(intermediate stages)`` and its terms.

        Args:
            out: :class:`lit3d.completion.generator.GeneratorOutput` of the partial inputs.
            target: ``(B, 1, R, R, R)`` float32 in {0, 1}.
            weight: factor of the final-stage BCE (``gamma`` with the critic on, else 1).
        Returns:
            (scalar fp32 loss, ``{"bce": ..., ["bce_stages": ...]}``).
        """
        hp = self.loss_weights
        bce = weighted_bce_with_logits(out.logits, target, hp.alpha)
        loss, terms = weight * bce, {"bce": bce}
        if hp.stage_weight > 0 and len(out.stage_logits) > 1:
            terms["bce_stages"] = self._stage_bce(out.stage_logits[:-1], target)
            loss = loss + hp.stage_weight * terms["bce_stages"]
        return loss, terms

    def _stage_bce(self, stage_logits: list[torch.Tensor], target: torch.Tensor) -> torch.Tensor:
        """Mean weighted BCE of the intermediate stages' (B, 1, r, r, r) logits against the
        target max-pooled to r^3 (a voxel of the coarse grid is occupied if any of its cell is)."""
        small = F.adaptive_max_pool3d(target.float(), stage_logits[0].shape[-3:])
        return torch.stack([weighted_bce_with_logits(lg, small, self.loss_weights.alpha) for lg in stage_logits]).mean()
