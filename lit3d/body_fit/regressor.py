"""A small CNN from a person's depth image to the body fit's parameters: the fit's start.

Trained on Anny people drawn and rendered on the fly (``lit3d-train experiment=body_regressor``:
:mod:`lit3d.body`, :mod:`datamodules.body`); used by ``lit3d-reconstruct --body --body-init CKPT``.

**Input** (:func:`crop`, the same for training and use): the foreground of the
:class:`~lit3d.body_fit.depth_points.Observation` (the points the fit sees) cropped to a square around its
bounding box (``margin`` of its longest side added on each side, centred; outside the image is
background), area-resampled to ``size x size``: channel 0 the foreground coverage in [0, 1],
channel 1 the depth minus the points' median depth, in units of ``depth_unit`` metres (0 on the
background). Beside the image, 3 numbers (the crop throws the metric size away): the bounding box's
height and width in metres at the median depth and the median depth, all in metres.

**Output** (:meth:`BodyRegressor.forward`, ``(B, 40)``; :func:`decode`): 6 phenotypes
(sigmoid, [0, 1]), 25 joint angles (sigmoid mapped onto each angle's limits), the global
rotation as 6 numbers (the first two columns of the matrix, Gram-Schmidt orthonormalised;
Zhou et al. 2019) and the translation, metres, relative to :func:`lit3d.body_fit.fit.start_centre`
of the points with ``depth_offset``. The scale is not predicted (``log_scale = 0``: metric depth).

**Checkpoint** (read with ``weights_only``): a ``lit3d-train experiment=body_regressor`` checkpoint (the
task's ``hyper_parameters`` ``preprocess`` and ``net``, its ``net.``-prefixed state dict; the shipped
``body-regressor`` is one, slimmed to fp16 by :func:`lit3d.zoo.slim.slim_checkpoint`), or this module's own
form ``{"format": FORMAT, "state_dict", "preprocess": Preprocess fields, "net": {"width", "hidden"}, "train"}``.
"""
from __future__ import annotations

import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch
from torch import nn

from lit3d.body_fit.errors import BodyCheckpointError
from lit3d.body_fit.fit import FitConfig, FitResult, fit_body, start_centre
from lit3d.body_fit.model import DOFS, PHENOTYPES, Body, Params
from lit3d.body_fit.depth_points import Observation
from lit3d.body_fit.results import fit_quality, render_mask
from lit3d.utils.checkpoints import META_KEY, load_checkpoint
from lit3d.utils.extras import require

FORMAT = "lit3d-body-regressor-1"
N_EXTRAS = 3  # bounding box height and width (m), median depth (m)
N_OUT = len(PHENOTYPES) + len(DOFS) + 6 + 3
TRANSLATION_UNIT = 0.1  # metres per unit of the raw translation outputs (keeps them near unit size)
# the refinement from the regressor's start (FitConfig's steps; the mean-body start runs 60 + 150), chosen on
# Anny validation people of body/pose seed 2000 (neither the evaluation's 1000 nor training's): 10 + 30 was as
# accurate as 10 + 40 and beat the optimisation alone, under 2 s CPU (10 + 20 left the posed body worse)
REFINE_GLOBAL_ITERS = 10
REFINE_FULL_ITERS = 30


@dataclass(frozen=True)
class Preprocess:
    """How a depth image becomes the regressor's input (module doc)."""

    size: int = 64            # pixels per side of the crop
    depth_unit: float = 0.5   # metres per unit of the relative-depth channel
    margin: float = 0.05      # share of the box's longest side added on each side
    depth_offset: float = 0.1  # metres: the translation is predicted relative to start_centre(points, this)


def crop(mask: np.ndarray, points: np.ndarray, fx: float, fy: float, prep: Preprocess) -> tuple[np.ndarray, np.ndarray]:
    """``(2, S, S) float32`` image and ``(3,) float32`` extras (module doc) of a foreground
    ``mask`` ``(H, W) bool`` whose pixels (``np.nonzero`` order) back-project to ``points`` ``(N, 3)``."""
    v, u = np.nonzero(mask)
    z = points[:, 2]
    med = float(np.median(z))
    r0, r1, c0, c1 = v.min(), v.max() + 1, u.min(), u.max() + 1
    side = int(np.ceil(max(r1 - r0, c1 - c0) * (1 + 2 * prep.margin)))
    top, left = (r0 + r1 - side) // 2, (c0 + c1 - side) // 2
    img = np.zeros((2, side, side), np.float32)
    img[0, v - top, u - left] = 1.0
    img[1, v - top, u - left] = (z - med) / prep.depth_unit
    t = torch.nn.functional.adaptive_avg_pool2d(torch.from_numpy(img)[None], prep.size)[0]
    cover = t[0]
    rel = torch.where(cover > 0, t[1] / cover.clamp(min=1e-6), torch.zeros(()))
    extras = np.array([(r1 - r0) * med / fy, (c1 - c0) * med / fx, med], np.float32)
    return torch.stack([cover, rel]).numpy(), extras


def crop_observation(obs: Observation, prep: Preprocess) -> tuple[np.ndarray, np.ndarray]:
    """:func:`crop` of an :class:`~lit3d.body_fit.depth_points.Observation`."""
    return crop(obs.mask, obs.points, obs.fx, obs.fy, prep)


def _block(c_in: int, c_out: int) -> nn.Sequential:
    return nn.Sequential(nn.Conv2d(c_in, c_out, 3, 2, 1, bias=False), nn.BatchNorm2d(c_out), nn.ReLU(inplace=True),
                         nn.Conv2d(c_out, c_out, 3, 1, 1, bias=False), nn.BatchNorm2d(c_out), nn.ReLU(inplace=True))


class BodyRegressor(nn.Module):
    """Strided conv blocks (``size`` halved down to 4, channels ``width``, ``2 width``...), then an
    MLP over the flattened features and the extras: ``(B, 2, S, S)``, ``(B, 3)`` -> ``(B, 40)``."""

    def __init__(self, size: int = 64, width: int = 32, hidden: int = 256):
        super().__init__()
        if size < 8 or size & (size - 1):
            raise ValueError(f"regressor input size {size}: expected a power of two >= 8")
        blocks, c = [], 2
        for k in range(int(np.log2(size)) - 2):
            blocks.append(_block(c, width * 2 ** k))
            c = width * 2 ** k
        self.features = nn.Sequential(*blocks)
        self.head = nn.Sequential(nn.Linear(c * 16 + N_EXTRAS, hidden), nn.ReLU(inplace=True), nn.Linear(hidden, N_OUT))
        lo = torch.tensor([d.lo for d in DOFS])
        self.register_buffer("lo", lo)
        self.register_buffer("span", torch.tensor([d.hi for d in DOFS]) - lo)

    def forward(self, image: torch.Tensor, extras: torch.Tensor) -> torch.Tensor:
        return self.head(torch.cat([self.features(image).flatten(1), extras], 1))

    def decode(self, out: torch.Tensor) -> dict[str, torch.Tensor]:
        """``(B, 40)`` raw outputs -> ``phenotype (B, 6)``, ``theta (B, D)``, ``rotmat (B, 3, 3)``,
        ``translation (B, 3)`` (relative, metres)."""
        n_p, n_d = len(PHENOTYPES), len(DOFS)
        return {"phenotype": torch.sigmoid(out[:, :n_p]),
                "theta": self.lo + self.span * torch.sigmoid(out[:, n_p:n_p + n_d]),
                "rotmat": rotmat_6d(out[:, n_p + n_d:n_p + n_d + 6]),
                "translation": TRANSLATION_UNIT * out[:, n_p + n_d + 6:]}


def rotmat_6d(x: torch.Tensor) -> torch.Tensor:
    """``(B, 6)`` -> ``(B, 3, 3)`` rotation matrices: the two 3-vectors Gram-Schmidt
    orthonormalised are the first two columns, their cross product the third."""
    a = nn.functional.normalize(x[:, :3], dim=1)
    b = nn.functional.normalize(x[:, 3:] - (a * x[:, 3:]).sum(1, keepdim=True) * a, dim=1)
    return torch.stack([a, b, torch.cross(a, b, dim=1)], 2)


def targets(phenotype: torch.Tensor, theta: torch.Tensor, rotation: torch.Tensor, translation: torch.Tensor) -> dict:
    """Training targets in :meth:`BodyRegressor.decode`'s form from ``(B, 6)``, ``(B, D)``,
    rotation vectors ``(B, 3)`` and relative translations ``(B, 3)``."""
    import roma

    return {"phenotype": phenotype, "theta": theta, "rotmat": roma.rotvec_to_rotmat(rotation), "translation": translation}


def loss(pred: dict, true: dict, w_translation: float = 100.0) -> tuple[torch.Tensor, dict[str, float]]:
    """Sum of mean squared errors: phenotype units, radians, rotation-matrix entries and metres
    (weighted by ``w_translation``: 10 cm counts as much as 1 rad)."""
    terms = {k: ((pred[k] - true[k]) ** 2).flatten(1).mean(1).mean() for k in ("phenotype", "theta", "rotmat", "translation")}
    terms["translation"] = w_translation * terms["translation"]
    return sum(terms.values()), {k: float(v.detach()) for k, v in terms.items()}


class Regressor:
    """A loaded regressor: :meth:`start` gives the fit's start for an observation."""

    def __init__(self, net: BodyRegressor, prep: Preprocess, path: str = "<memory>"):
        self.net, self.prep, self.path = net.eval(), prep, path

    def predict(self, obs: Observation) -> dict[str, torch.Tensor]:
        """:meth:`BodyRegressor.decode` of one observation (batch dimension dropped)."""
        img, extras = crop_observation(obs, self.prep)
        with torch.no_grad():
            out = self.net.decode(self.net(torch.from_numpy(img)[None], torch.from_numpy(extras)[None]))
        return {k: v[0] for k, v in out.items()}

    def start(self, obs: Observation) -> Params:
        """The predicted :class:`~lit3d.body_fit.model.Params` of ``obs`` (``log_scale = 0``)."""
        import roma

        out = self.predict(obs)
        centre = torch.from_numpy(start_centre(obs.points, self.prep.depth_offset)).float()
        return Params(out["phenotype"].clone(), out["theta"].clone(), roma.rotmat_to_rotvec(out["rotmat"]).float(),
                      centre + out["translation"], torch.zeros(()))


def refine_config(global_iters: int = REFINE_GLOBAL_ITERS, full_iters: int = REFINE_FULL_ITERS,
                  base: FitConfig | None = None, poor_extra_iters: int = 0) -> FitConfig:
    """``base`` (default :class:`~lit3d.body_fit.fit.FitConfig`) with the refinement's step counts and
    ``poor_extra_iters`` (:func:`fit_from_regressor`)."""
    return FitConfig(**{**(base or FitConfig()).__dict__, "global_iters": global_iters, "full_iters": full_iters,
                        "poor_extra_iters": poor_extra_iters})


def regress(body: Body, regressor: Regressor, obs: Observation) -> FitResult:
    """The regressor alone, as a :class:`~lit3d.body_fit.fit.FitResult` (no step; ``seconds``: the
    crop, the network and the body's vertices)."""
    t0 = time.perf_counter()
    p = regressor.start(obs)
    with torch.no_grad():
        verts = body.camera_vertices(p).double().numpy()
    return FitResult(p, verts, [], {}, time.perf_counter() - t0, 0)


def fit_from_regressor(body: Body, regressor: Regressor, obs: Observation, cfg: FitConfig | None = None) -> FitResult:
    """:func:`~lit3d.body_fit.fit.fit_body` from the regressor's start with ``cfg`` (default
    :func:`refine_config`). Where ``cfg.poor_extra_iters`` > 0 and that fit is flagged poor
    (:func:`lit3d.body_fit.results.fit_quality`), the fit goes on from where it ended for that many more
    full steps (a fresh schedule). ``seconds`` counts the prediction and the check too."""
    cfg = cfg or refine_config()
    t0 = time.perf_counter()
    res = fit_body(body, obs, cfg, regressor.start(obs))
    if cfg.poor_extra_iters > 0 and fit_quality(body, res, obs, render_mask(res.vertices, body.faces, obs))["poor_fit"]:
        more = fit_body(body, obs, FitConfig(**{**cfg.__dict__, "global_iters": 0, "full_iters": cfg.poor_extra_iters}),
                        res.params)
        more.history, more.iterations = res.history + more.history, res.iterations + more.iterations
        res = more
    res.seconds = time.perf_counter() - t0
    return res


def checkpoint(net: BodyRegressor, prep: Preprocess, net_args: dict, train: dict) -> dict:
    """The dict :func:`torch.save` writes (module doc)."""
    return {"format": FORMAT, "state_dict": net.state_dict(), "preprocess": asdict(prep), "net": dict(net_args),
            "train": train}


def _from_task_checkpoint(ck: dict) -> dict:
    """A ``lit3d-train experiment=body_regressor`` checkpoint (Lightning's: the task's hyper-parameters
    and ``net.``-prefixed state dict) in this module's checkpoint form."""
    hp = ck.get("hyper_parameters") or {}
    state = {k[len("net."):]: v for k, v in ck["state_dict"].items() if k.startswith("net.")}
    if not state:
        raise KeyError("no net.* weights in its state dict")
    return {"format": FORMAT, "state_dict": state, "preprocess": dict(hp.get("preprocess") or {}),
            "net": dict(hp.get("net") or {})}


def load_regressor(path: str | Path) -> Regressor:
    """The :class:`Regressor` of a checkpoint (this module's format, or a ``lit3d-train
    experiment=body_regressor`` checkpoint); any problem is one :class:`BodyCheckpointError` line naming
    the file; :class:`~lit3d.utils.extras.MissingExtra` without ``lit3d[body]`` (it fits Anny)."""
    require("body", "the body regressor")
    ck = load_checkpoint(path, BodyCheckpointError)
    if isinstance(ck, dict) and ((ck.get(META_KEY) or {}).get("task") or {}).get("name") == "body":
        try:
            ck = _from_task_checkpoint(ck)
        except (KeyError, TypeError, AttributeError) as exc:
            raise BodyCheckpointError(f"{path}: body task checkpoint without its regressor: {exc}") from None
    if not isinstance(ck, dict) or ck.get("format") != FORMAT:
        found = ck.get("format") if isinstance(ck, dict) else type(ck).__name__
        raise BodyCheckpointError(f"{path}: not a body regressor checkpoint (format {found!r}, expected {FORMAT!r}; "
                                  "made by lit3d-train experiment=body_regressor)")
    try:
        prep = Preprocess(**ck["preprocess"])
        net = BodyRegressor(prep.size, **ck["net"])
        net.load_state_dict(ck["state_dict"])
    except (KeyError, TypeError, ValueError, RuntimeError) as exc:
        detail = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise BodyCheckpointError(f"{path}: body regressor checkpoint does not fit this version: {detail}") from None
    return Regressor(net, prep, str(path))
