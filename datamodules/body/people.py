"""Anny people drawn and rendered on the fly: the body regressor's training and validation samples.

Each person: a phenotype from Anny's adult shape distribution (as the evaluation's held-out people,
``sample_phenotype(..., "adult")``: ``SimpleShapeDistribution`` at morphological ages
:data:`~lit3d.body_model.bodies.ADULT_AGES`, drawn a batch at a time), a pose of the mix
``placement.poses`` (:func:`lit3d.body_fit.poses.draw_pose`; ``upright``: the Anny data source's
:func:`~lit3d.body_model.bodies.sample_pose`, its ``root`` yaw the global rotation; ``varied`` adds
people turned any way, folded and in any rotation), placed ``placement.distance`` metres in front of
the camera (uniform in the range) and up to ``placement.lateral`` metres off the axis, rendered
through the evaluation's camera and ``placement.sensor``'s noise
(:func:`lit3d.body_fit.synthetic.sensed_depth`), then cropped as the regressor sees it
(:func:`lit3d.body_fit.regressor.crop`).

A sample (one person): ``image (2, S, S) float32``, ``extras (3,) float32`` and the targets of
:func:`lit3d.body_fit.regressor.targets`: ``phenotype (6,)``, ``theta (D,)``, ``rotmat (3, 3)``,
``translation (3,)`` metres, relative to the regressor's start centre.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from lit3d.body_fit.depth_points import MIN_POINTS
from lit3d.body_fit.fit import start_centre
from lit3d.body_fit.model import PHENOTYPES, Body
from lit3d.body_fit.poses import POSE_MIXES, draw_pose
from lit3d.body_fit.regressor import Preprocess, crop, targets
from lit3d.body_fit.synthetic import HEIGHT, WIDTH, sensed_depth
from lit3d.body_model.bodies import adult_shape_distribution
from lit3d.sensing.camera import backproject
from lit3d.sensing.sensor import SENSORS

# body/pose draws that training and validation must not use: the evaluation's held-out people (1000) and
# the draw the refinement's step counts were chosen on (2000)
HELD_OUT_SEEDS = (1000, 2000)


@dataclass(frozen=True)
class Placement:
    """Where the drawn people stand and how they are sensed (module doc)."""

    distance: tuple[float, float] = (2.6, 4.0)  # metres from the camera, uniform in the range
    lateral: float = 0.3                        # metres off the optical axis at most (x; y half of it)
    sensor: str = "recgan"                      # noise model (lit3d.sensing.sensor.SENSORS)
    poses: str = "upright"                      # pose mix (lit3d.body_fit.poses.POSE_MIXES)
    image: tuple[int, int] = (WIDTH, HEIGHT)    # rendered image (width, height) in pixels

    def __post_init__(self):
        if self.sensor not in SENSORS:
            raise ValueError(f"placement.sensor={self.sensor!r}: expected one of {', '.join(sorted(SENSORS))}")
        if self.poses not in POSE_MIXES:
            raise ValueError(f"placement.poses={self.poses!r}: expected one of {', '.join(sorted(POSE_MIXES))}")
        lo, hi = self.distance
        if not 0 < lo <= hi:
            raise ValueError(f"placement.distance={list(self.distance)}: expected 0 < near <= far (metres)")
        object.__setattr__(self, "distance", (float(lo), float(hi)))
        object.__setattr__(self, "image", tuple(int(v) for v in self.image))


def shape_distribution(body: Body):
    """Anny's adult shape distribution (as ``sample_phenotype(..., "adult")``)."""
    return adult_shape_distribution(body.model.model)


def draw_people(body: Body, dist, seed: int, first: int, n: int, cam, prep: Preprocess,
                placement: Placement = Placement()) -> dict[str, torch.Tensor]:
    """People ``first .. first + n - 1`` of draw ``seed`` (module doc), rendered and cropped by
    :func:`render_people`: a dict of ``(n', ...)`` tensors, ``n' <= n``."""
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(int(np.random.default_rng([seed, first, 41]).integers(2**31)))
        _, ph = dist.sample(n)
    pheno = torch.stack([ph[k].float() for k in PHENOTYPES], 1)
    drawn = [draw_pose(seed, first + i, placement.poses)[:2] for i in range(n)]
    theta = torch.tensor(np.stack([p[0] for p in drawn]), dtype=torch.float32)
    rot = torch.tensor(np.stack([p[1] for p in drawn]), dtype=torch.float32)
    rng = np.random.default_rng([seed, first, 43])
    lateral, (near, far) = placement.lateral, placement.distance
    trans = np.stack([rng.uniform(-lateral, lateral, n), rng.uniform(-lateral, lateral, n) / 2,
                      rng.uniform(near, far, n)], 1)
    return render_people(body, pheno, theta, rot, trans, cam, prep, rng, placement.sensor, placement.image)


def render_people(body: Body, pheno: torch.Tensor, theta: torch.Tensor, rot: torch.Tensor, trans: np.ndarray, cam,
                  prep: Preprocess, rng: np.random.Generator, sensor: str = "recgan",
                  image=(WIDTH, HEIGHT)) -> dict[str, torch.Tensor]:
    """``n`` bodies of phenotypes ``(n, 6)``, joint angles ``(n, D)``, camera-frame rotation vectors
    ``(n, 3)`` and translations ``(n, 3)`` (metres; ``log_scale = 0``) through ``sensor``
    (:func:`lit3d.body_fit.synthetic.sensed_depth`, ``cam`` seeing an ``image`` (width, height)),
    cropped: ``image (n', 2, S, S)``, ``extras (n', 3)`` and the targets of
    :func:`lit3d.body_fit.regressor.targets` (``n' <= n``: a body with fewer than MIN_POINTS foreground
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
