"""Human bodies from the Anny parametric model (PyPI ``anny``; code Apache-2.0, MakeHuman assets CC0).

A subject is a point of Anny's phenotype space (gender, age, muscle, weight, height, proportions,
each in [0, 1]) drawn with a seed from adult ranges (:data:`PHENOTYPE_RANGES`). A pose is a set
of joint rotations drawn within per-joint limits (:data:`JOINT_LIMITS`: spine, neck, shoulders,
elbows, hips, knees) plus a turn about the vertical axis. Pose ``p`` is the same body pose for
every subject (the SHREC'14 / FAUST convention), so poses are split units as subjects are.
The canonical pose is Anny's rest pose (an A-pose) with no turn.

Axes: Anny is z-up and faces -y; its ``local-ref`` pose parameters are rotations about axes that
are aligned with those world axes at rest (x: the body's left, y: backwards, z: up). Meshes come
out y-up, facing +z (towards lit3d's depth camera): ``(x, y, z) -> (x, z, -y)``.

    model = BodyModel()                                   # loads anny (cache: $ANNY_CACHE_DIR)
    verts = model.vertices(phenotype, [pose_a, pose_b])   # list of (V, 3) float32, y up
    model.faces                                           # (F, 3) int64 triangles

The first start of ``anny`` builds a cache of about 790 MB (about 2.5 min on 2 cores;
``ANNY_CACHE_DIR`` moves it, default ``~/.cache/anny``); ``make install`` builds it once. That build
says what it does and how long it has left, and the first Ctrl-C ends it within 2 s
(:mod:`lit3d.body_model.anny_cache`).
"""
from __future__ import annotations

import contextlib
import math
import os
import sys
from dataclasses import dataclass

import numpy as np

from lit3d.body_model.anny_cache import first_build

# Bump when the sampling below changes: it is part of every Anny cache's config hash.
BODIES_VERSION = "anny-bodies-1"  # phenotypes="adult" adds its own tag (datamodules.canonical.datamodule)

# Adult subjects: Anny's age anchors are newborn 0 (-1/3 extrapolated), baby 0, child 1/3,
# young 2/3, old 1; 0.55 is a teenager.
PHENOTYPE_RANGES: dict[str, tuple[float, float]] = {
    "gender": (0.0, 1.0),
    "age": (0.55, 1.0),
    "muscle": (0.1, 0.9),
    "weight": (0.1, 0.9),
    "height": (0.0, 1.0),
    "proportions": (0.2, 0.8),
}


@dataclass(frozen=True)
class Joint:
    """Limits (radians) of one joint's rotation about Anny's rest axes x, y, z; ``mirror``: the
    right-side twin of a left joint (y and z rotations change sign)."""

    bone: str
    x: tuple[float, float] = (0.0, 0.0)
    y: tuple[float, float] = (0.0, 0.0)
    z: tuple[float, float] = (0.0, 0.0)


# Left-side limits; the right side is drawn independently from the mirrored ranges.
# Shoulder: +y lowers the left arm (rest: about 45 degrees down), -y raises it above the head;
# -x swings it forward. Hip: -x flexes (leg forward), +y crosses the midline. Knee: +x bends.
# Elbow flexion is about the axis across the A-pose upper arm (see ``ELBOW_AXIS``).
JOINT_LIMITS: tuple[Joint, ...] = (
    Joint("spine03", x=(-0.15, 0.45), y=(-0.25, 0.25), z=(-0.35, 0.35)),
    Joint("spine01", x=(-0.1, 0.3), y=(-0.15, 0.15), z=(-0.2, 0.2)),
    Joint("neck01", x=(-0.3, 0.4), y=(-0.25, 0.25), z=(-0.5, 0.5)),
    Joint("upperarm01.L", x=(-1.4, 0.5), y=(-1.4, 0.6), z=(-0.5, 0.5)),
    Joint("upperleg01.L", x=(-1.3, 0.35), y=(-0.4, 0.1), z=(-0.3, 0.3)),
    Joint("lowerleg01.L", x=(0.0, 1.9)),
)
ELBOW = ("lowerarm01.L", 0.0, 2.1)  # bone, flexion range (radians)
# The left forearm's flexion axis at rest: across the A-pose arm (out and down) and forwards (-y).
ELBOW_AXIS = np.cross(np.array([1.0, 0.0, -1.0]) / math.sqrt(2.0), np.array([0.0, -1.0, 0.0]))


def anny_version() -> str:
    """The installed ``anny`` version (part of the cache hash: another release may pose differently)."""
    from importlib.metadata import version

    return version("anny")


def right_of(bone: str) -> str:
    return bone[:-2] + ".R"


PHENOTYPE_MODES = ("uniform", "adult")
ADULT_AGES = (20.0, 65.0)  # morphological ages (years) of Anny's shape distribution for phenotypes="adult"


def sample_phenotype(seed: int, index: int, mode: str = "uniform", model=None) -> dict[str, float]:
    """Subject ``index`` of the phenotype draw ``seed``: ``{label: value in [0, 1]}``.

    ``uniform``: each label uniform in :data:`PHENOTYPE_RANGES` (heights up to 2.36 m, teenagers);
    ``adult``: Anny's own shape distribution (``anny.shape_distribution.SimpleShapeDistribution``:
    height, weight, muscle and proportions conditioned on age and gender, calibrated on WHO data) at
    morphological ages :data:`ADULT_AGES`; needs the loaded Anny ``model``."""
    if mode == "uniform":
        rng = np.random.default_rng([int(seed), int(index), 31])
        return {k: float(rng.uniform(lo, hi)) for k, (lo, hi) in PHENOTYPE_RANGES.items()}
    if mode != "adult":
        raise ValueError(f"unknown phenotype mode '{mode}' ({', '.join(PHENOTYPE_MODES)})")
    import torch

    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(int(np.random.default_rng([int(seed), int(index), 37]).integers(2**31)))
        _, pheno = adult_shape_distribution(model).sample(1)
    return {k: float(pheno[k][0]) for k in PHENOTYPE_RANGES}


def adult_shape_distribution(model):
    """Anny's own shape distribution (``SimpleShapeDistribution`` of the loaded Anny ``model``) at
    morphological ages :data:`ADULT_AGES`: the ``adult`` phenotype draw."""
    import torch
    from anny.shape_distribution import SimpleShapeDistribution

    ages = torch.distributions.Uniform(torch.tensor(ADULT_AGES[0]), torch.tensor(ADULT_AGES[1]))
    return SimpleShapeDistribution(model, morphological_age_distribution=ages)


def sample_pose(pose_seed: int, index: int, strength: float = 1.0, yaw_range: float = 15.0,
                subject: int | None = None) -> dict[str, np.ndarray]:
    """Pose ``index`` of the draw ``pose_seed``: ``{bone: rotation vector (3,) float64}`` in Anny's
    rest axes, each joint's angles uniform within its limits times ``strength``; the ``root`` entry
    turns the body by U(-yaw_range, yaw_range) degrees about the vertical. ``subject`` (an index):
    that subject's own pose ``index``, a draw no other subject shares (None: pose ``index`` of every
    subject, the shared draw)."""
    key = [int(pose_seed), int(index), 53] if subject is None else [int(pose_seed), int(subject), int(index), 59]
    rng = np.random.default_rng(key)
    out: dict[str, np.ndarray] = {}
    for j in JOINT_LIMITS:
        sides = [(j.bone, 1.0), (right_of(j.bone), -1.0)] if j.bone.endswith(".L") else [(j.bone, 1.0)]
        for bone, sign in sides:
            x, y, z = (float(rng.uniform(lo, hi)) * strength for lo, hi in (j.x, j.y, j.z))
            out[bone] = np.array([x, sign * y, sign * z])
    bone, lo, hi = ELBOW
    for b, sign in ((bone, 1.0), (right_of(bone), -1.0)):
        axis = ELBOW_AXIS * np.array([1.0, sign, sign])  # mirrored across the x = 0 plane
        out[b] = axis * float(rng.uniform(lo, hi)) * strength
    out["root"] = np.array([0.0, 0.0, math.radians(float(rng.uniform(-yaw_range, yaw_range)))])
    return out


def anny_to_y_up(verts: np.ndarray) -> np.ndarray:
    """Anny's +z up, facing -y -> lit3d's +y up, facing +z: ``(x, y, z) -> (x, z, -y)``."""
    return np.stack([verts[:, 0], verts[:, 2], -verts[:, 1]], 1)


@contextlib.contextmanager
def _native_stderr_closed(active: bool):
    """Send file descriptor 2 to /dev/null inside the block (native libraries' prints that Python
    cannot filter); Python exceptions still propagate and print after it."""
    if not active:
        yield
        return
    sys.stderr.flush()
    saved, null = os.dup(2), os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(null, 2)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)
        os.close(null)


class BodyModel:
    """The Anny model (loaded on first use) posing one subject in several poses at once."""

    def __init__(self):
        self._model = None

    @property
    def model(self):
        if self._model is None:
            import torch

            # warp (anny's skinning) notes from native code on stderr that a CPU machine has no CUDA
            # driver, and prints a banner (devices, kernel cache) on every start: both at its init, done
            # here, so that stderr is open again for the first build's lines
            with _native_stderr_closed(not torch.cuda.is_available()):
                import warp

                warp.config.log_level = warp.LOG_ERROR
                import anny

                warp.init()
            with first_build():  # silent when anny's cache is there
                self._model = anny.Anny().to(dtype=torch.float32)
        return self._model

    @property
    def faces(self) -> np.ndarray:
        """``(F, 3) int64`` triangles, shared by every body."""
        return self.model.faces.cpu().numpy().astype(np.int64)

    def vertices(self, phenotype: dict[str, float], poses: list[dict[str, np.ndarray] | None]) -> list[np.ndarray]:
        """``(V, 3) float32`` y-up vertices (metres) of ``phenotype`` in each of ``poses``
        (``None`` = the rest pose)."""
        import roma
        import torch

        m = self.model
        labels = list(m.bone_labels)
        params = torch.eye(4)[None, None].repeat(len(poses), m.bone_count, 1, 1)
        for i, pose in enumerate(poses):
            for bone, rotvec in (pose or {}).items():
                params[i, labels.index(bone), :3, :3] = roma.rotvec_to_rotmat(torch.as_tensor(rotvec, dtype=torch.float32))
        pheno = {k: torch.full((len(poses),), float(v)) for k, v in phenotype.items()}
        with torch.no_grad():
            verts = m(pose_parameters=params, phenotype_kwargs=pheno)["vertices"].cpu().numpy()
        return [anny_to_y_up(v).astype(np.float32) for v in verts]
