"""FLOPs and activation memory of one completion training step, counted on the meta device.

The step of :meth:`lit3d.completion.module.CompletionTask.training_step` (manual optimisation) is run
part by part through the task's own methods (:mod:`lit3d.completion.objectives`), on meta tensors
under :class:`lit3d.utils.step_cost.CostCounter` (PyTorch's FLOP formulas) and
:class:`lit3d.utils.step_cost.SavedBytes`, so the count follows the training code and its switches
(``critic_steps``, ``gp_every``, ``critic_concat``, ``adversarial``, the net sizes):

    critic fakes    generator forward without a graph               x critic_steps
    critic scores   critic on real + fake, forward + backward       x critic_steps
    critic penalty  WGAN-GP: forward, input gradient, its backward  x critic_steps / gp_every
    generator       generator + critic + classifier, fwd + bwd      x 1

Optimiser updates and element-wise work are not counted (no FLOP formula; small beside the convs).
"""
from __future__ import annotations

import torch

from lit3d.completion.losses import critic_loss
from lit3d.utils.step_cost import CostCounter, SavedBytes

META = torch.device("meta")
PARTS = ("critic fakes", "critic scores", "critic penalty", "generator")


def _on_meta(task) -> None:
    if any(p.device.type != "meta" for p in task.parameters()):
        raise ValueError("step cost: build the task on the meta device (with torch.device('meta'): ...)")


def _inputs(task, batch: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Meta ``x`` (B, 1, r, r, r), ``y`` (B, 1, R, R, R) and CPU labels (B,) (all seen: the classifier runs)."""
    r, big = int(task.net_cfg["in_res"]), int(task.net_cfg["out_res"])
    x = task._fmt(torch.zeros(batch, 1, r, r, r, device=META))
    y = task._fmt(torch.zeros(batch, 1, big, big, big, device=META))
    n = max(int(task.net_cfg["n_classes"]), 1)
    return x, y, torch.arange(batch) % n


def _measure(task, batch: int) -> dict[str, dict]:
    """FLOPs, ops and peak saved bytes of each part at ``batch`` (one run of each)."""
    x, y, labels = _inputs(task, batch)
    adversarial = task.critic is not None
    out: dict[str, dict] = {}
    if adversarial:
        with CostCounter() as c:
            fake = task.critic_fakes(x)
        out["critic fakes"] = {"flops": c.flops, "ops": c.ops, "saved": 0}
        # one critic update: both graphs alive until its one backward (the memory peak), each part's FLOPs apart
        scores, penalty = CostCounter(), CostCounter()
        with SavedBytes() as saved:
            with scores:
                d_real, d_fake = task.critic_scores(x, y, fake)
                loss = critic_loss(d_fake, d_real, torch.zeros((), device=META), 0.0)
            with penalty:
                gp, _ = task.critic_penalty(x, y, fake)
                gp_loss = task.adversarial.gp_lambda * task.adversarial.gp_every * gp
            critic_peak = saved.peak
            with scores:
                loss.backward()
            with penalty:
                gp_loss.backward()
        del loss, gp_loss, d_real, d_fake, gp
        with SavedBytes() as alone:  # the update without the penalty (gp_every > 1: most updates)
            d_real, d_fake = task.critic_scores(x, y, fake)
            no_gp_peak = alone.peak
        del d_real, d_fake
        out["critic scores"] = {"flops": scores.flops, "ops": scores.ops, "saved": no_gp_peak}
        out["critic penalty"] = {"flops": penalty.flops, "ops": penalty.ops, "saved": critic_peak - no_gp_peak}
    with CostCounter() as c, SavedBytes() as saved:
        loss_g, _, _ = task.generator_objective(x, y, labels, adversarial)
        peak = saved.peak
        loss_g.backward()
    out["generator"] = {"flops": c.flops, "ops": c.ops, "saved": peak}
    task.zero_grad(set_to_none=True)
    return out


def completion_step_cost(task) -> dict:
    """The cost of one training step of ``task`` (a :class:`~lit3d.completion.module.CompletionTask` built on
    the meta device), per sample.

    Returns:
        ``{"parts": [{"part", "runs", "flops", "ops", "saved_bytes"}], "flops", "ops", "saved_bytes"}``:
        per part one run's FLOPs per sample, its aten ops (kernel launches, any batch), its saved-for-backward
        bytes per sample (the slope between batch 1 and 2: parameters drop out) and ``runs`` per training step
        (``critic_steps``; ``critic_steps / gp_every`` for the penalty); the totals weigh each part by its runs
        (``saved_bytes``: the step's peak, the larger of a critic update with the penalty and the generator's).
    """
    _on_meta(task)
    hp = task.adversarial
    one, two = _measure(task, 1), _measure(task, 2)
    runs = {"critic fakes": hp.critic_steps, "critic scores": hp.critic_steps,
            "critic penalty": hp.critic_steps / hp.gp_every, "generator": 1}
    parts = [{"part": p, "runs": runs[p], "flops": two[p]["flops"] - one[p]["flops"], "ops": one[p]["ops"],
              "saved_bytes": two[p]["saved"] - one[p]["saved"]} for p in PARTS if p in one]
    by = {p["part"]: p for p in parts}
    critic_update = by["critic scores"]["saved_bytes"] + by["critic penalty"]["saved_bytes"] if "critic scores" in by else 0
    return {"parts": parts, "flops": sum(p["runs"] * p["flops"] for p in parts),
            "ops": sum(p["runs"] * p["ops"] for p in parts),
            "saved_bytes": max(critic_update, by["generator"]["saved_bytes"])}
