"""Fit Anny (:class:`lit3d.body_fit.model.Body`) to an :class:`lit3d.body_fit.depth_points.Observation` by Adam,
from the mean body facing the camera.

Loss (metres; ``X`` the camera-frame vertices ``(V, 3)``, ``P`` the sampled points ``(M, 3)``):

- **point-to-surface**, one-sided, observed points to the body's visible surface: each point's
  nearest *front-facing* vertex (vertex normal towards the camera; found with a k-d tree on the
  detached vertices, so the match is fixed within an iteration and the distance is
  differentiable), distance ``sqrt(a |P - X|^2 + (1 - a) ((P - X) . n)^2 + eps)``: a mix of
  point-to-vertex and point-to-plane (the tangent plane at that vertex, ``a = 0.3``), which
  approximates the point-to-triangle distance on Anny's ~1-2 cm vertex spacing;
- **silhouette**, rasterisation-free: every vertex projected through the camera samples (bilinear,
  :func:`torch.nn.functional.grid_sample`) the distance transform of the foreground mask's
  outside (:attr:`~lit3d.body_fit.depth_points.Observation.outside_px`), converted to metres at the vertex's
  depth (``px z / fx``); 0 for a vertex inside the silhouette. The reverse direction (the mask
  covered by the body) is the point-to-surface term's job;
- **priors**: ``w_pose * sum(theta^2)`` (angles in radians), ``w_pheno * sum((phenotype - 0.5)^2)``,
  ``w_scale * log_scale^2`` (metric depth: the scale stays near 1 and the height phenotype does the
  work), and ``w_limits * sum(excess^2)`` for angles or phenotypes outside their limits (the output
  is clamped to them).

Stages: ``global_iters`` steps move the rest-pose mean body (translation and scale only, and no
silhouette term: the mean body's A-pose arms stick out of most silhouettes, and a free rotation
turns the body sideways to hide them; no Anny forward pass, cheap); then ``full_iters`` steps move everything, the learning rates
decaying linearly to 10% over the second half.

:func:`fit_best`: the same from several starts (:func:`start_variants`: the mean body, turned
either way, arms lowered), each probed for a few steps; the lowest loss goes on.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import torch

from lit3d.body_fit.model import DOFS, Body, Params
from lit3d.body_fit.depth_points import Observation
from lit3d.body_fit.surface import point_to_surface, silhouette_excess


@dataclass
class FitConfig:
    """Step counts, learning rates and loss weights of :func:`fit_body` (see the module doc)."""

    global_iters: int = 60
    full_iters: int = 150
    lr: dict = field(default_factory=lambda: {"phenotype": 0.02, "theta": 0.03, "rotation": 0.01,
                                              "translation": 0.005, "log_scale": 0.005})
    lr_global: float = 0.02
    point_mix: float = 0.3       # a: the point-to-vertex share of the point-to-surface distance
    w_silhouette: float = 1.0
    w_pose: float = 1e-4
    w_pheno: float = 1e-4
    w_scale: float = 0.3
    w_limits: float = 1.0
    depth_offset: float = 0.1    # metres: the start's centre lies this far behind the points' median
    poor_extra_iters: int = 0    # lit3d.body_fit.regressor.fit_from_regressor: full steps more when flagged poor


@dataclass
class FitResult:
    """A finished fit: ``params`` (detached), camera-frame ``vertices`` ``(V, 3) float64``,
    ``history`` (total loss per step), ``terms`` (the last step's loss terms), ``seconds``."""

    params: Params
    vertices: np.ndarray
    history: list[float]
    terms: dict[str, float]
    seconds: float
    iterations: int


def _loss(body: Body, verts: torch.Tensor, p: Params, obs: Observation, pts: torch.Tensor, outside: torch.Tensor,
          cfg: FitConfig, silhouette: bool = True) -> tuple[torch.Tensor, dict[str, float]]:
    terms = {
        "point_to_surface": point_to_surface(verts, body.faces, pts, cfg.point_mix, body.incidence).mean(),
        "silhouette": cfg.w_silhouette * silhouette_excess(verts, obs, outside).mean() if silhouette
        else torch.zeros(()),
        "pose_prior": cfg.w_pose * (p.theta ** 2).sum(),
        "phenotype_prior": cfg.w_pheno * ((p.phenotype - 0.5) ** 2).sum(),
        "scale_prior": cfg.w_scale * p.log_scale ** 2,
        "limits": cfg.w_limits * ((body.limit_excess(p.theta) ** 2).sum()
                                  + (torch.relu(p.phenotype - 1) ** 2 + torch.relu(-p.phenotype) ** 2).sum()),
    }
    total = sum(terms.values())
    return total, {k: float(v.detach()) for k, v in terms.items()}


def start_centre(points: np.ndarray, depth_offset: float) -> np.ndarray:
    """``(3,)``: the centre of camera-frame ``points`` ``(N, 3)``'s bounding box in x and y, their
    median depth pushed back by ``depth_offset`` metres in z (where a start body's centre goes)."""
    lo, hi = points.min(0), points.max(0)
    return np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, np.median(points[:, 2]) + depth_offset])


def start_params(obs: Observation, cfg: FitConfig) -> Params:
    """The mean body, upright, facing the camera, centred on the points' bounding box (x, y) and
    their median depth pushed back by ``cfg.depth_offset`` (:func:`start_centre`)."""
    return Params.mean(tuple(float(c) for c in start_centre(obs.points, cfg.depth_offset)))


def fit_body(body: Body, obs: Observation, cfg: FitConfig | None = None, start: Params | None = None) -> FitResult:
    """Fit ``body`` to ``obs`` (see the module doc); ``start``: initial parameters (default
    :func:`start_params`)."""
    cfg = cfg or FitConfig()
    t0 = time.perf_counter()
    p = (start or start_params(obs, cfg)).detached()
    pts = torch.from_numpy(obs.sample)
    outside = torch.from_numpy(obs.outside_px)[None, None]
    history: list[float] = []
    terms: dict[str, float] = {}

    with torch.no_grad():
        base = body.anny_vertices(p.phenotype, p.theta)
    rigid = [p.translation, p.log_scale]
    for t in rigid:
        t.requires_grad_(True)
    opt = torch.optim.Adam(rigid, lr=cfg.lr_global)
    for _ in range(cfg.global_iters):
        opt.zero_grad()
        loss, terms = _loss(body, body.place(base, p), p, obs, pts, outside, cfg, silhouette=False)
        loss.backward()
        opt.step()
        history.append(float(loss.detach()))

    tensors = p.tensors()
    for t in tensors.values():
        t.requires_grad_(True)
    opt = torch.optim.Adam([{"params": [t], "lr": cfg.lr[k]} for k, t in tensors.items()])
    for i in range(cfg.full_iters):
        decay = 1.0 - 0.9 * max(0.0, (i - cfg.full_iters / 2) / max(cfg.full_iters / 2, 1))
        for g, k in zip(opt.param_groups, tensors):
            g["lr"] = cfg.lr[k] * decay
        opt.zero_grad()
        loss, terms = _loss(body, body.camera_vertices(p), p, obs, pts, outside, cfg)
        loss.backward()
        opt.step()
        history.append(float(loss.detach()))

    with torch.no_grad():
        p = p.detached()
        p.theta.copy_(torch.maximum(torch.minimum(p.theta, body.hi), body.lo))
        p.phenotype.clamp_(0.0, 1.0)
        verts = body.camera_vertices(p).double().numpy()
    return FitResult(p, verts, history, terms, time.perf_counter() - t0, cfg.global_iters + cfg.full_iters)


def start_variants(obs: Observation, cfg: FitConfig, yaw: float = 0.4, arms: float = 0.5) -> list[Params]:
    """Starts for :func:`fit_best`: the mean body (:func:`start_params`), turned by ``-yaw`` and
    ``+yaw`` radians about the vertical, and with both arms lowered by ``arms`` radians towards the
    sides (the shoulders' ``y`` angle; the rest pose is an A-pose)."""
    base = start_params(obs, cfg)
    out = [base]
    for sign in (-1.0, 1.0):
        p = base.detached()
        p.rotation[1] = sign * yaw  # camera y is the vertical
        out.append(p)
    p = base.detached()
    for k, d in enumerate(DOFS):
        if d.bone.startswith("upperarm01") and abs(d.axis[1]) == 1.0:
            p.theta[k] = arms  # the right side's axis is mirrored: the same angle lowers it too
    out.append(p)
    return out


def fit_best(body: Body, obs: Observation, cfg: FitConfig | None = None, probe_iters: int = 40,
             starts: list[Params] | None = None) -> FitResult:
    """Fit from several starts (:func:`start_variants`): each runs the rigid stage and ``probe_iters``
    full steps; the one with the lowest loss goes on with the whole schedule of ``cfg`` (a fresh
    ``full_iters`` from where its probe ended, no second rigid stage). ``seconds`` and
    ``iterations`` count every start."""
    cfg = cfg or FitConfig()
    t0 = time.perf_counter()
    probe_cfg = FitConfig(**{**cfg.__dict__, "full_iters": probe_iters})
    probes = [fit_body(body, obs, probe_cfg, s) for s in (starts or start_variants(obs, cfg))]
    best = min(range(len(probes)), key=lambda i: probes[i].history[-1])
    res = fit_body(body, obs, FitConfig(**{**cfg.__dict__, "global_iters": 0}), probes[best].params)
    res.history = probes[best].history + res.history
    res.terms = {**res.terms, "start": best, "probe_losses": [p.history[-1] for p in probes]}
    res.seconds = time.perf_counter() - t0
    res.iterations = sum(p.iterations for p in probes) + res.iterations
    return res
