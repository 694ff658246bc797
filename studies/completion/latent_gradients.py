"""Per-group gradient RMS and Adam update/weight ratios of the completion generator at initialisation.

    .venv/bin/python -m studies.completion.latent_gradients [--scale demo|paper] [--batch B] [--steps N] [overrides ...]

Builds ``CompletionTask`` from ``experiment=completion_<scale>`` (plus Hydra overrides, e.g.
``task.latent_grad_scale=1``), draws B synthetic furniture samples (``datamodules.completion``), and
for each named parameter group of ``CompletionTask.health_groups()`` prints:

    grad_rms      RMS over the group's elements of d(reconstruction loss)/d(param) at init
                  (the loss as logged: the per-voxel mean, before task.optimizer.loss_scale)
    grad/eps      grad_rms / the generator optimiser's eps (= task.optimizer.eps / loss_scale, which is the
                  same as scaling the loss): below 1, Adam's update shrinks by about that factor
    upd/w step1   |dw| / |w| of the first Adam step (generator optimiser of the task, its lr/eps)
    upd/w stepN   |w_N - w_0| / |w_0| after N steps on the same batch

The loss is the task's reconstruction loss (weighted BCE of the final stage + stage_weight x the
intermediate stages), i.e. what the generator trains on before the critic joins. One thread.
"""
from __future__ import annotations

import argparse
import time

import numpy as np
import torch
from hydra import compose, initialize_config_dir
from hydra.utils import instantiate

from datamodules.completion.depth_voxels import make_sample
from datamodules.completion.furniture import make_shape
from lit3d.runtime.compose import CONF_DIR
from lit3d.utils.shapenet_categories import SEEN_CATEGORIES


def batch(n: int, res: int, seed: int = 0) -> tuple[torch.Tensor, torch.Tensor]:
    """``n`` synthetic samples: (input (n, 1, res/4, ...)^3, target (n, 1, res, ...)^3) float32 {0, 1}."""
    rng = np.random.default_rng(seed)
    xs, ys = [], []
    for i in range(n):
        shape = make_shape(SEEN_CATEGORIES[i % len(SEEN_CATEGORIES)], rng)
        s = make_sample(shape, (float(rng.uniform(0, 360)), 30.0, 0.0), target_res=res)
        xs.append(torch.from_numpy(s["input"]).float())
        ys.append(torch.from_numpy(s["target"]).float())
    return torch.stack(xs)[:, None], torch.stack(ys)[:, None]


def rms(ts) -> float:
    ts = [t for t in ts if t is not None]
    n = sum(t.numel() for t in ts)
    return float(torch.sqrt(sum(t.double().pow(2).sum() for t in ts) / max(n, 1)))


def norm(ts) -> float:
    return float(torch.sqrt(sum(t.double().pow(2).sum() for t in ts)))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scale", choices=("demo", "paper"), default="demo")
    ap.add_argument("--batch", type=int, default=None, help="default: the experiment's data.batch_size")
    ap.add_argument("--steps", type=int, default=5)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("overrides", nargs="*")
    args = ap.parse_args()
    torch.set_num_threads(1)
    torch.manual_seed(args.seed)
    with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
        cfg = compose(config_name="train", overrides=[f"experiment=completion_{args.scale}", *args.overrides])
    task = instantiate(cfg.task, _convert_="all")
    res = int(cfg.task.nets.out_res)
    b = args.batch or int(cfg.data.batch_size)
    t0 = time.time()
    x, y = batch(b, res, args.seed)
    print(f"scale={args.scale} overrides={args.overrides} batch={b} grid {x.shape[-1]}^3 -> {res}^3 "
          f"occupancy input {x.mean():.3f} target {y.mean():.3f} (data {time.time() - t0:.0f}s)")
    groups = {k: v for k, v in task.health_groups().items() if k not in ("critic", "classifier")}
    opts = task.configure_optimizers()
    opt = opts[0] if isinstance(opts, (list, tuple)) else opts
    eps = min(g["eps"] for g in opt.param_groups)
    w0 = {k: [p.detach().clone() for p in ps] for k, ps in groups.items()}
    task.train()
    grads, step1, acts = {}, {}, {}
    stage = task.generator.stages[0]
    hook = stage.fc_enc.register_forward_hook(lambda m, i, o: acts.setdefault("l", o.detach()))
    t0 = time.time()
    for step in range(args.steps):
        opt.zero_grad(set_to_none=True)
        out = task.generator(x)
        loss, _ = task.reconstruction_loss(out, y)
        loss.backward()
        if step == 0:
            hook.remove()
            grads = {k: rms([p.grad for p in ps]) for k, ps in groups.items()}
            print(f"loss {float(loss):.4f}; stage 1 latent l rms {rms([acts['l']]):.3g}; "
                  f"fwd+bwd {time.time() - t0:.1f}s")
        opt.step()
        if step == 0:
            step1 = {k: norm([p.detach() - w for p, w in zip(ps, w0[k])]) / max(norm(w0[k]), 1e-30)
                     for k, ps in groups.items()}
    stepn = {k: norm([p.detach() - w for p, w in zip(ps, w0[k])]) / max(norm(w0[k]), 1e-30)
             for k, ps in groups.items()}
    print(f"{'group':24s} {'params':>11s} {'grad_rms':>10s} {'grad/eps':>10s} {'upd/w step1':>12s} "
          f"{'upd/w step' + str(args.steps):>12s}")
    for k, ps in groups.items():
        n = sum(p.numel() for p in ps)
        print(f"{k:24s} {n:11d} {grads[k]:10.2e} {grads[k] / eps:10.2e} {step1[k]:12.2e} {stepn[k]:12.2e}")


if __name__ == "__main__":
    main()
