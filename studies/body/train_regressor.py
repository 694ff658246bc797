"""Train :mod:`lit3d.body.regressor` on Anny people drawn and rendered on the fly.

    python -m studies.body.train_regressor --out CKPT [--minutes 40] [--steps 20000] [--size 64] ...

Each person: a phenotype from Anny's adult shape distribution (as the evaluation's held-out people,
``sample_phenotype(..., "adult")``: ``SimpleShapeDistribution`` at morphological ages
:data:`~lit3d.body_model.bodies.ADULT_AGES`, drawn a batch at a time), a pose of the mix
``--poses`` (:func:`lit3d.body.poses.draw_pose`; ``upright``: the Anny data source's
:func:`~lit3d.body_model.bodies.sample_pose`, its ``root`` yaw the global rotation; ``varied``
adds people turned any way, folded and in any rotation), placed ``--distance`` metres in front of
the camera (uniform in the range) and up to ``--lateral`` metres off the axis, rendered through the
evaluation's camera and ``--sensor`` noise (:func:`lit3d.body.synthetic.sensed_depth`). Seeds:
``--seed`` for training, ``--seed + 1`` for the fixed validation draw printed in the log; the
evaluation's 1000 and the refinement's validation draw 2000 are refused. Nothing is cached on disk: the samples live in a
replay buffer in memory (``--buffer`` people; each is used about ``--reuse`` times).

Loss: :func:`lit3d.body.regressor.loss`; Adam, learning rate cosine-decayed over whichever ends
first, ``--steps`` or ``--minutes``. Writes CKPT (:func:`lit3d.body.regressor.checkpoint`) every
``--save-every`` steps and at the end; one JSON line per ``--log-every`` steps on stdout.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np
import torch

from lit3d.body_model.bodies import adult_shape_distribution
from lit3d.body.fit import start_centre
from lit3d.body.model import PHENOTYPES, Body
from lit3d.body.depth_points import MIN_POINTS
from lit3d.body.poses import POSE_MIXES, draw_pose
from lit3d.body.regressor import BodyRegressor, Preprocess, checkpoint, crop, loss, targets
from lit3d.body.synthetic import HEIGHT, WIDTH, Camera, sensed_depth
from lit3d.sensing.camera import backproject

HELD_OUT_SEEDS = (1000, 2000)  # the evaluation's people, the refinement's validation people


def shape_distribution(body: Body):
    """Anny's adult shape distribution (as ``sample_phenotype(..., "adult")``)."""
    return adult_shape_distribution(body.model.model)


def draw(body: Body, dist, seed: int, first: int, n: int, cam, prep: Preprocess, distance=(2.6, 4.0),
         lateral: float = 0.3, sensor: str = "recgan", image=(WIDTH, HEIGHT),
         poses: str = "upright") -> dict[str, torch.Tensor]:
    """People ``first .. first + n - 1`` of draw ``seed`` (module doc) in poses of the mix ``poses``
    (:data:`lit3d.body.poses.POSE_MIXES`), rendered and cropped by :func:`render_people` (``cam``
    sees an ``image`` (width, height) in pixels)."""
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(int(np.random.default_rng([seed, first, 41]).integers(2**31)))
        _, ph = dist.sample(n)
    pheno = torch.stack([ph[k].float() for k in PHENOTYPES], 1)
    drawn = [draw_pose(seed, first + i, poses)[:2] for i in range(n)]
    theta = torch.tensor(np.stack([p[0] for p in drawn]), dtype=torch.float32)
    rot = torch.tensor(np.stack([p[1] for p in drawn]), dtype=torch.float32)
    rng = np.random.default_rng([seed, first, 43])
    trans = np.stack([rng.uniform(-lateral, lateral, n), rng.uniform(-lateral, lateral, n) / 2,
                      rng.uniform(distance[0], distance[1], n)], 1)
    return render_people(body, pheno, theta, rot, trans, cam, prep, rng, sensor, image)


def render_people(body: Body, pheno: torch.Tensor, theta: torch.Tensor, rot: torch.Tensor, trans: np.ndarray, cam,
                  prep: Preprocess, rng: np.random.Generator, sensor: str = "recgan",
                  image=(WIDTH, HEIGHT)) -> dict[str, torch.Tensor]:
    """``n`` bodies of phenotypes ``(n, 6)``, joint angles ``(n, D)``, camera-frame rotation vectors
    ``(n, 3)`` and translations ``(n, 3)`` (metres; ``log_scale = 0``) through ``sensor``
    (:func:`lit3d.body.synthetic.sensed_depth`, ``cam`` seeing an ``image`` (width, height)),
    cropped: ``image (n', 2, S, S)``, ``extras (n', 3)`` and the targets of
    :func:`lit3d.body.regressor.targets` (``n' <= n``: a body with fewer than MIN_POINTS foreground
    pixels is left out)."""
    import roma

    with torch.no_grad():
        anny = body.batch_anny_vertices(pheno, theta)
        rotm = roma.rotvec_to_rotmat(rot) @ body.to_camera
        verts = torch.einsum("bij,bvj->bvi", rotm, anny - body.centre).double().numpy() + trans[:, None]
    faces, keep, imgs, extras, rel = body.faces, [], [], [], []
    for i in range(len(verts)):
        depth, _ = sensed_depth(verts[i], faces, cam, rng, sensor, *image)
        mask = depth > 0
        if mask.sum() < MIN_POINTS:
            continue
        pts = backproject(depth, cam, mask)
        img, ex = crop(mask, pts, cam.fx, cam.fy, prep)
        keep.append(i)
        imgs.append(img)
        extras.append(ex)
        rel.append(trans[i] - start_centre(pts, prep.depth_offset))
    k = torch.tensor(keep, dtype=torch.long)
    return {"image": torch.from_numpy(np.stack(imgs)), "extras": torch.from_numpy(np.stack(extras)),
            **targets(pheno[k], theta[k], rot[k], torch.tensor(np.stack(rel), dtype=torch.float32))}


class Buffer:
    """A ring of at most ``cap`` samples (the dicts :func:`draw` gives), images kept as float16."""

    def __init__(self, cap: int):
        self.cap, self.n, self.at, self.data = cap, 0, 0, {}

    def add(self, batch: dict[str, torch.Tensor]) -> None:
        m = len(batch["image"])
        if not self.data:
            self.data = {k: torch.zeros((self.cap, *v.shape[1:]), dtype=torch.float16 if k == "image" else v.dtype)
                         for k, v in batch.items()}
        idx = (self.at + torch.arange(m)) % self.cap
        for k, v in batch.items():
            self.data[k][idx] = v.to(self.data[k].dtype)
        self.at, self.n = (self.at + m) % self.cap, min(self.n + m, self.cap)

    def sample(self, b: int, gen: torch.Generator) -> dict[str, torch.Tensor]:
        idx = torch.randint(self.n, (min(b, self.n),), generator=gen)
        return {k: v[idx].float() for k, v in self.data.items()}


def step(net: BodyRegressor, opt, batch: dict[str, torch.Tensor], lr: float) -> dict[str, float]:
    """One Adam step on ``batch``; its loss terms."""
    net.train()
    for g in opt.param_groups:
        g["lr"] = lr
    total, terms = loss(net.decode(net(batch["image"], batch["extras"])), batch)
    opt.zero_grad()
    total.backward()
    opt.step()
    return {**terms, "total": float(total.detach())}


def validate(net: BodyRegressor, val: dict[str, torch.Tensor]) -> dict[str, float]:
    """Loss terms and mean absolute phenotype (units) / joint-angle (radians) errors on ``val``."""
    net.eval()
    with torch.no_grad():
        pred = net.decode(net(val["image"], val["extras"]))
    _, terms = loss(pred, val)
    return {**terms, "phenotype_mae": float((pred["phenotype"] - val["phenotype"]).abs().mean()),
            "theta_mae": float((pred["theta"] - val["theta"]).abs().mean()),
            "translation_mae_m": float((pred["translation"] - val["translation"]).abs().mean())}


def _save(path: Path, ck: dict) -> None:
    tmp = path.with_name(path.name + ".tmp")
    torch.save(ck, tmp)
    os.replace(tmp, path)


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="python -m studies.body.train_regressor", description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, required=True, help="checkpoint file to write")
    ap.add_argument("--steps", type=int, default=20000, help="training steps at most")
    ap.add_argument("--minutes", type=float, default=40.0, help="wall-clock minutes at most")
    ap.add_argument("--batch", type=int, default=64, help="people per training step")
    ap.add_argument("--draw", type=int, default=32, help="people drawn and rendered at a time")
    ap.add_argument("--reuse", type=float, default=8.0, help="training uses of each drawn person (about)")
    ap.add_argument("--buffer", type=int, default=20000, help="people kept in memory")
    ap.add_argument("--val", type=int, default=128, help="validation people (seed + 1)")
    ap.add_argument("--size", type=int, default=64, help="input crop side in pixels (a power of two)")
    ap.add_argument("--depth-unit", type=float, default=0.5, help="metres per unit of the depth channel")
    ap.add_argument("--width", type=int, default=32, help="channels of the first conv block")
    ap.add_argument("--hidden", type=int, default=256, help="hidden units of the head")
    ap.add_argument("--lr", type=float, default=1e-3, help="Adam learning rate (cosine-decayed)")
    ap.add_argument("--distance", type=float, nargs=2, default=(2.6, 4.0), help="metres from the camera (range)")
    ap.add_argument("--lateral", type=float, default=0.3, help="metres off the optical axis at most (x; y half)")
    ap.add_argument("--sensor", default="recgan", help="noise model (lit3d.sensing.sensor.SENSORS)")
    ap.add_argument("--poses", choices=sorted(POSE_MIXES), default="upright",
                    help="pose mix of the people (lit3d.body.poses): upright as the Anny data source, or varied")
    ap.add_argument("--seed", type=int, default=7, help="body/pose draw of the training people")
    ap.add_argument("--threads", type=int, default=1, help="torch CPU threads")
    ap.add_argument("--log-every", type=int, default=100, help="steps between log lines")
    ap.add_argument("--save-every", type=int, default=1000, help="steps between checkpoints")
    return ap


def main(argv: list[str] | None = None) -> dict:
    args = _parser().parse_args(argv)
    if {args.seed, args.seed + 1} & set(HELD_OUT_SEEDS):
        raise SystemExit(f"--seed {args.seed}: seeds {HELD_OUT_SEEDS} (and the one below them) are held out")
    torch.set_num_threads(args.threads)
    torch.manual_seed(args.seed)
    prep = Preprocess(size=args.size, depth_unit=args.depth_unit)
    net_args = {"width": args.width, "hidden": args.hidden}
    net = BodyRegressor(args.size, **net_args)
    opt = torch.optim.Adam(net.parameters(), lr=args.lr)
    body, cam = Body(), Camera.default()
    dist = shape_distribution(body)
    place = {"distance": tuple(args.distance), "lateral": args.lateral, "sensor": args.sensor, "poses": args.poses}
    val = draw(body, dist, args.seed + 1, 0, args.val, cam, prep, **place)
    buf, gen = Buffer(args.buffer), torch.Generator().manual_seed(args.seed)
    t0, drawn, credit, running, log = time.perf_counter(), 0, 0.0, [], []
    train = {**{k: v for k, v in vars(args).items() if k != "out"}, "started": time.strftime("%Y-%m-%d %H:%M:%S")}
    it = 0
    while it < args.steps and time.perf_counter() - t0 < 60 * args.minutes:
        batch = draw(body, dist, args.seed, drawn, args.draw, cam, prep, **place)
        drawn += args.draw
        buf.add(batch)
        credit += args.reuse * len(batch["image"]) / args.batch
        while credit >= 1 and it < args.steps:
            frac = max(it / args.steps, (time.perf_counter() - t0) / (60 * args.minutes))
            running.append(step(net, opt, buf.sample(args.batch, gen), args.lr * 0.5 * (1 + math.cos(math.pi * min(frac, 1)))))
            credit -= 1
            it += 1
            if it % args.log_every == 0:
                mean = {k: float(np.mean([r[k] for r in running])) for k in running[0]}
                line = {"step": it, "drawn": drawn, "minutes": (time.perf_counter() - t0) / 60, "train": mean,
                        "val": validate(net, val)}
                log.append(line)
                running = []
                print(json.dumps(line), flush=True)
            if it % args.save_every == 0:
                _save(args.out, checkpoint(net, prep, net_args, {**train, "steps_done": it, "drawn": drawn, "log": log}))
    final = {"step": it, "drawn": drawn, "minutes": (time.perf_counter() - t0) / 60, "val": validate(net, val)}
    log.append(final)
    print(json.dumps(final), flush=True)
    _save(args.out, checkpoint(net, prep, net_args, {**train, "steps_done": it, "drawn": drawn, "log": log,
                                                     "preprocess": asdict(prep)}))
    print(f"wrote {args.out}", file=sys.stderr)
    return final


if __name__ == "__main__":
    main()
