"""The top-K latent selector learns and is dynamic, at the demo experiment's sizes.

Bound used below: after 3 generator Adam steps on one batch, every stage's selector weight net
moves by |dw|/|w| >= 0.1 x that stage's encoder convs (measured with the default loss_scale
"voxels": 0.5-0.85 x; with the literal per-voxel mean, loss_scale=1, the last stage's selector
moves 1e-4 x its encoder, i.e. it is a fixed random mask; studies/completion/latent_gradients.py).
"""
from __future__ import annotations

import numpy as np
import pytest
import torch
from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra
from omegaconf import OmegaConf

from datamodules.completion.depth_voxels import make_sample
from datamodules.completion.furniture import make_shape
from lit3d.callbacks.health import group_stats
from lit3d.runtime.compose import CONF_DIR
from lit3d.completion.checkpoint_upgrade import upgrade_hparams
from lit3d.completion.losses import resolve_loss_scale
from lit3d.completion.module import CompletionTask
from lit3d.completion.selector import LatentSelector
from lit3d.utils.shapenet_categories import SEEN_CATEGORIES

BOUND = 0.1  # selector update ratio / encoder update ratio, same stage
STEPS = 3


pytestmark = pytest.mark.usefixtures("one_torch_thread")


@pytest.fixture(scope="module")
def demo_task_kwargs() -> dict:
    """``task`` of ``experiment=completion_demo`` as plain constructor arguments."""
    GlobalHydra.instance().clear()
    try:
        with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
            cfg = compose(config_name="train", overrides=["experiment=completion_demo"])
        kw = OmegaConf.to_container(cfg.task, resolve=True)
    finally:
        GlobalHydra.instance().clear()
    kw.pop("_target_")
    return kw


@pytest.fixture(scope="module")
def furniture_batch(demo_task_kwargs) -> tuple[torch.Tensor, torch.Tensor]:
    """4 synthetic furniture views: input (4, 1, 16, 16, 16), target (4, 1, 64, 64, 64) float32 {0, 1}."""
    rng = np.random.default_rng(0)
    res = demo_task_kwargs["nets"]["out_res"]
    xs, ys = [], []
    for i in range(4):
        s = make_sample(make_shape(SEEN_CATEGORIES[i], rng), (float(rng.uniform(0, 360)), 30.0, 0.0), target_res=res)
        xs.append(torch.from_numpy(s["input"]).float())
        ys.append(torch.from_numpy(s["target"]).float())
    return torch.stack(xs)[:, None], torch.stack(ys)[:, None]


def _task(kw: dict, **changes) -> CompletionTask:
    torch.manual_seed(0)
    kw = {**kw, **changes, "nets": {**kw["nets"], **changes.pop("nets", {})}} if "nets" in changes else {**kw, **changes}
    return CompletionTask(**upgrade_hparams(kw))  # changes by their short names (loss_scale=1.0) into their nodes


def _update_ratios(task: CompletionTask, batch, steps: int = STEPS) -> dict[str, float]:
    """|w_steps - w_0| / |w_0| per health group after ``steps`` generator Adam steps on ``batch``
    (the task's reconstruction loss and its generator optimiser)."""
    x, y = batch
    groups = task.health_groups()
    before = {k: [p.detach().clone() for p in ps] for k, ps in groups.items()}
    opts = task.configure_optimizers()
    opt = opts[0] if isinstance(opts, (list, tuple)) else opts
    for _ in range(steps):
        opt.zero_grad(set_to_none=True)
        loss, _ = task.reconstruction_loss(task.generator(x), y)
        loss.backward()
        opt.step()
    return {k: group_stats(ps, before[k])["update_ratio"] for k, ps in groups.items()}


def _selector_vs_encoder(ratios: dict[str, float], stages: int) -> list[float]:
    return [ratios[f"stage {s} selector"] / ratios[f"stage {s} encoder"] for s in range(1, stages + 1)]


def assert_selectors_learn(task: CompletionTask, batch) -> None:
    rel = _selector_vs_encoder(_update_ratios(task, batch), len(task.generator.stages))
    assert min(rel) >= BOUND, f"selector / encoder update ratio per stage {[f'{r:.2g}' for r in rel]} (bound {BOUND})"


def test_selector_weight_net_moves_like_the_encoder(demo_task_kwargs, furniture_batch):
    assert_selectors_learn(_task(demo_task_kwargs), furniture_batch)


def test_frozen_selector_fails_the_bound(demo_task_kwargs, furniture_batch):
    task = _task(demo_task_kwargs)
    for stage in task.generator.stages:
        stage.selector.weight_net.requires_grad_(False)
    with pytest.raises(AssertionError, match="selector / encoder"):
        assert_selectors_learn(task, furniture_batch)


def test_per_voxel_mean_without_scale_starves_the_last_selector(demo_task_kwargs, furniture_batch):
    """The selector's old fault, kept measurable: loss_scale=1 leaves the gradient below Adam's eps
    (last stage's selector / encoder measured 0.0015; 0.00012 without selector_norm)."""
    rel = _selector_vs_encoder(_update_ratios(_task(demo_task_kwargs, loss_scale=1.0), furniture_batch), 3)
    assert rel[-1] < 0.1 * BOUND


def test_normalised_selector_survives_a_grown_latent():
    """The latent grows during training (RMS 0.05 -> 8-23 in 6 demo epochs, where the trained weight
    net gives |z| = 60-450 before its sigmoid): without selector_norm the sigmoid saturates and the
    weight net's gradient vanishes; with it the mask depends on the latent's direction only and the
    gradient stays. A latent of RMS 400 gives |z| ~ 100 with these untrained weights."""
    torch.manual_seed(0)
    latent = torch.randn(4, 256)
    rms = {}
    for norm in (False, True):
        torch.manual_seed(1)
        sel = LatentSelector(256, 16, "straight_through", normalize=norm)
        if norm:
            assert torch.equal(sel(latent)[1], sel(400 * latent)[1])
        big = (400 * latent).requires_grad_(True)
        out, _ = sel(big)
        out.pow(2).sum().backward()
        rms[norm] = group_stats(list(sel.weight_net.parameters()))["grad_rms"]
    assert rms[True] > 1e3 * rms[False]


def _generator_optimizer(task: CompletionTask) -> torch.optim.Optimizer:
    """The generator's Adam (``configure_optimizers`` returns it alone without a critic)."""
    opts = task.configure_optimizers()
    return opts[0] if isinstance(opts, (list, tuple)) else opts


def test_loss_scale_is_adams_eps_and_keeps_the_logged_loss(demo_task_kwargs, furniture_batch):
    task = _task(demo_task_kwargs)
    r = demo_task_kwargs["nets"]["out_res"]
    assert demo_task_kwargs["optimizer"]["loss_scale"] == "voxels" and task.loss_scale == r**3
    opt_g = _generator_optimizer(task)
    assert opt_g.param_groups[0]["eps"] == pytest.approx(demo_task_kwargs["optimizer"]["eps"] / r**3)
    x, y = furniture_batch
    with torch.no_grad():
        loss, terms = task.reconstruction_loss(task.generator(x), y)
    assert 0.05 < float(terms["bce"]) < 1.0  # still the per-voxel mean (log 2 x (1 + alpha) / 2 at init)
    assert resolve_loss_scale(2.5, r) == 2.5
    for bad in ("sum", 0.0, -1.0):
        with pytest.raises(ValueError, match="loss_scale"):
            resolve_loss_scale(bad, r)


def _kept_masks(task: CompletionTask, x: torch.Tensor) -> list[torch.Tensor]:
    """Per stage the selector's keep mask ``(B, n)`` float {0, 1} for the inputs ``x``."""
    masks = []
    hooks = [s.selector.register_forward_hook(lambda m, i, o: masks.append(o[1])) for s in task.generator.stages]
    with torch.no_grad():
        task.generator(x)
    for h in hooks:
        h.remove()
    return masks


def test_kept_set_differs_between_inputs(demo_task_kwargs, furniture_batch):
    """Dynamic: at initialisation every pair of the 4 inputs keeps a different set at every stage
    (overlap 0.93-0.94 of K here: the latent is dominated by a part common to all inputs; after
    the 6-epoch run of studies/completion/short_completion_run.py stages 2 and 3 share 0.70 / 0.47 of K on
    average), and a sample's set depends on that sample alone (not on the rest of the batch)."""
    task = _task(demo_task_kwargs)
    x, _ = furniture_batch
    k = demo_task_kwargs["nets"]["k"]
    masks = _kept_masks(task, x)
    for mask in masks:  # (B, n) per stage, k ones per row
        assert (mask.sum(1) == k).all()
        overlap = (mask[:, None] * mask[None]).sum(-1)[~torch.eye(len(mask), dtype=torch.bool)] / k
        assert float(overlap.max()) < 1.0, "two inputs keep the same latent entries"
        assert int(mask.amax(0).sum()) > k  # more than K entries are used across the batch
    flipped = _kept_masks(task, x.flip(0))
    assert all(torch.equal(a, b.flip(0)) for a, b in zip(masks, flipped))


def test_straight_through_feeds_the_weight_net_and_literal_does_not(demo_task_kwargs, furniture_batch):
    """README "Design choices": literal = eq. 3.1 as written (no gradient to the weight net);
    straight_through = hard mask forward, gradient to w backward, above Adam's effective eps."""
    x, y = furniture_batch
    grads, outs = {}, {}
    for mode in ("straight_through", "literal"):
        task = _task(demo_task_kwargs, nets={"selector_mode": mode})
        out = task.generator(x)
        outs[mode] = out.logits.detach()
        task.reconstruction_loss(out, y)[0].backward()
        eps = _generator_optimizer(task).param_groups[0]["eps"]
        grads[mode] = [group_stats(list(s.selector.parameters()))["grad_rms"] / eps for s in task.generator.stages]
    assert torch.equal(outs["straight_through"], outs["literal"])  # same forward value
    assert grads["literal"] == [0.0, 0.0, 0.0]
    assert min(grads["straight_through"]) > 1.0
