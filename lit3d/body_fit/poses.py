"""Poses of the regressor's training people (:mod:`datamodules.body.people`), drawn from a mix of
pose families.

The Anny data source (:func:`lit3d.body_model.bodies.sample_pose`) draws upright people: each
joint uniform within :data:`~lit3d.body_model.bodies.JOINT_LIMITS`, the body turned by at most
15 degrees about the vertical. People lying on their side, kneeling, crawling or upside down are
outside it, and a regressor trained on it starts their fits far off (TOSCA's humans,
docs/results_canonical.md). The families (:data:`FAMILIES`):

- ``upright``: :func:`sample_pose` unchanged (joint angles and its ``root`` yaw);
- ``turned``: the same joints, the body turned by any angle about the vertical;
- ``folded``: hips flexed (``U(lo, 0)`` of each hip's flexion) and knees bent (``U(0.9, hi)``
  rad), both sides drawn apart; the body leaned forward or back by up to 90 degrees, then turned by
  any angle about the vertical (kneeling, crouching, crawling, a high kick);
- ``any``: the same joints as ``upright``, the body in a rotation drawn uniformly over all of them
  (lying, on its side, upside down).

The joint angles stay within the fit's limits (:data:`lit3d.body_fit.model.DOFS`). A mix
(:data:`POSE_MIXES`) gives each family's share; ``upright`` alone reproduces the draw of the
first regressors.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.spatial.transform import Rotation

from lit3d.body_model.bodies import sample_pose
from lit3d.body_fit.model import ANNY_TO_CAMERA, DOFS

FAMILIES = ("upright", "turned", "folded", "any")
POSE_MIXES: dict[str, dict[str, float]] = {
    "upright": {"upright": 1.0},
    "varied": {"upright": 0.35, "turned": 0.15, "folded": 0.2, "any": 0.3},
}
KNEE_BENT = 0.9  # radians: the least knee flexion of a folded pose


def pose_params(pose: dict) -> tuple[np.ndarray, np.ndarray]:
    """A :func:`sample_pose` pose -> ``(D,)`` joint angles of :data:`lit3d.body_fit.model.DOFS` and the
    ``(3,)`` camera-frame rotation vector of its ``root`` turn."""
    theta = np.array([float(np.dot(pose[d.bone], d.axis)) for d in DOFS])
    return theta, ANNY_TO_CAMERA @ np.asarray(pose.get("root", np.zeros(3)), np.float64)


def _fold(theta: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """``theta`` ``(D,)`` with both hips flexed and both knees bent (module doc)."""
    out = theta.copy()
    for k, d in enumerate(DOFS):
        if d.bone.startswith("upperleg01") and d.axis[0] == 1.0:  # hip flexion (-x flexes)
            out[k] = rng.uniform(d.lo, 0.0)
        elif d.bone.startswith("lowerleg01"):
            out[k] = rng.uniform(KNEE_BENT, d.hi)
    return out


def draw_pose(seed: int, index: int, mix: str = "upright") -> tuple[np.ndarray, np.ndarray, str]:
    """Person ``index`` of draw ``seed`` under pose mix ``mix`` (:data:`POSE_MIXES`): ``(D,)`` joint
    angles, the ``(3,)`` camera-frame rotation vector of the body and the family drawn."""
    shares = POSE_MIXES[mix]
    theta, rot = pose_params(sample_pose(seed, index, subject=index))
    if set(shares) == {"upright"}:
        return theta, rot, "upright"
    rng = np.random.default_rng([int(seed), int(index), 61])
    names = list(shares)
    family = names[int(rng.choice(len(names), p=np.array([shares[n] for n in names]) / sum(shares.values())))]
    yaw = Rotation.from_rotvec([0.0, rng.uniform(-math.pi, math.pi), 0.0])  # camera y is the vertical
    if family == "turned":
        rot = yaw.as_rotvec()
    elif family == "folded":
        theta = _fold(theta, rng)
        lean = Rotation.from_rotvec([rng.uniform(-math.pi / 2, math.pi / 2), 0.0, 0.0])  # about camera x
        rot = (yaw * lean).as_rotvec()
    elif family == "any":
        rot = Rotation.random(random_state=rng).as_rotvec()
    return theta, np.asarray(rot, np.float64), family
