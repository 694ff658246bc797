"""Differentiable Anny: fit parameters -> camera-frame body vertices.

Parameters (all torch tensors, float32; :class:`Params`):

- ``phenotype`` ``(6,)``: Anny's default phenotypes (gender, age, muscle, weight, height,
  proportions), each in [0, 1] (clamped in the forward pass; 0.5 = the mean body);
- ``theta`` ``(D,)``: joint angles in radians, one per degree of freedom of :data:`DOFS`: the
  bones and limits of the data source (:data:`lit3d.body_model.bodies.JOINT_LIMITS`: spine03,
  spine01, neck01 with 3 axes, shoulders and hips with 3 axes per side, knees 1 axis, elbows 1 axis
  about ``ELBOW_AXIS``; ``D = 25``). A bone's rotation vector (Anny's rest axes, ``local-ref``) is
  the sum of its angles times their axes, so a pose of :func:`~lit3d.body_model.bodies.sample_pose`
  (without its ``root`` turn) is a point of this space;
- ``rotation`` ``(3,)``: rotation vector of the body in the camera frame (0: facing the camera,
  upright);
- ``translation`` ``(3,)`` metres and ``log_scale`` ``()``.

Camera-frame vertices ``(V, 3)`` = ``exp(log_scale) R(rotation) C (v_anny - c0) + translation``
with ``C`` Anny's z-up, facing -y frame -> the camera's (x right, y down, z forward; the body faces
the camera) and ``c0`` the mean body's rest-pose bounding-box centre.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from lit3d.body_model.bodies import ELBOW, ELBOW_AXIS, JOINT_LIMITS, BodyModel, anny_to_y_up, right_of
from lit3d.body_fit.surface import incidence_matrix
from lit3d.utils.extras import require

PHENOTYPES = ("gender", "age", "muscle", "weight", "height", "proportions")
# Anny (x, y, z; z up, facing -y) -> camera (x right, y down, z forward): (x, -z, y); a rotation (det +1)
ANNY_TO_CAMERA = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


@dataclass(frozen=True)
class Dof:
    """One joint angle: ``bone`` turns by the angle about ``axis`` (Anny's rest axes), ``lo <= angle <= hi``."""

    bone: str
    axis: tuple[float, float, float]
    lo: float
    hi: float


def _dofs() -> tuple[Dof, ...]:
    out = []
    for j in JOINT_LIMITS:
        sides = [(j.bone, 1.0), (right_of(j.bone), -1.0)] if j.bone.endswith(".L") else [(j.bone, 1.0)]
        for bone, sign in sides:
            for k, (lo, hi) in enumerate((j.x, j.y, j.z)):
                if lo == hi == 0.0:
                    continue
                axis = [0.0, 0.0, 0.0]
                axis[k] = 1.0 if k == 0 else sign  # the right side mirrors y and z (as sample_pose draws it)
                out.append(Dof(bone, tuple(axis), float(lo), float(hi)))
    bone, lo, hi = ELBOW
    for b, sign in ((bone, 1.0), (right_of(bone), -1.0)):
        out.append(Dof(b, tuple(float(a) for a in ELBOW_AXIS * np.array([1.0, sign, sign])), float(lo), float(hi)))
    return tuple(out)


DOFS = _dofs()


@dataclass
class Params:
    """The fitted quantities (see the module doc); :meth:`mean` is the start of a fit."""

    phenotype: torch.Tensor    # (6,)
    theta: torch.Tensor        # (D,)
    rotation: torch.Tensor     # (3,)
    translation: torch.Tensor  # (3,)
    log_scale: torch.Tensor    # ()

    @classmethod
    def mean(cls, translation=(0.0, 0.0, 2.5)) -> "Params":
        return cls(torch.full((len(PHENOTYPES),), 0.5), torch.zeros(len(DOFS)), torch.zeros(3),
                   torch.tensor(translation, dtype=torch.float32), torch.zeros(()))

    def tensors(self) -> dict[str, torch.Tensor]:
        return {k: getattr(self, k) for k in ("phenotype", "theta", "rotation", "translation", "log_scale")}

    def detached(self) -> "Params":
        return Params(**{k: v.detach().clone() for k, v in self.tensors().items()})


class Body:
    """Anny posed by :class:`Params` (see the module doc); ``model``: a loaded
    :class:`~lit3d.body_model.bodies.BodyModel` (loads anny on first use)."""

    def __init__(self, model: BodyModel | None = None):
        require("body", "the Anny body fit")
        self.model = model or BodyModel()
        anny = self.model.model
        labels = list(anny.bone_labels)
        self.bones = sorted({d.bone for d in DOFS}, key=labels.index)
        self.bone_index = torch.tensor([labels.index(b) for b in self.bones])
        # (B_sel, 3, D): theta -> each selected bone's rotation vector
        w = torch.zeros(len(self.bones), 3, len(DOFS))
        for k, d in enumerate(DOFS):
            w[self.bones.index(d.bone), :, k] = torch.tensor(d.axis)
        self.dof_axes = w
        self.lo = torch.tensor([d.lo for d in DOFS])
        self.hi = torch.tensor([d.hi for d in DOFS])
        self.to_camera = torch.tensor(ANNY_TO_CAMERA, dtype=torch.float32)
        self.faces = self.model.faces
        with torch.no_grad():
            rest = self.anny_vertices(torch.full((len(PHENOTYPES),), 0.5), None)
        self.centre = (rest.min(0).values + rest.max(0).values) / 2
        self.incidence = incidence_matrix(self.faces, rest.shape[0])  # (V, F) for vertex normals

    def bone_rotvecs(self, theta: torch.Tensor) -> torch.Tensor:
        """``(D,)`` angles -> ``(B_sel, 3)`` rotation vectors of :attr:`bones`."""
        return torch.einsum("bkd,d->bk", self.dof_axes, theta)

    def anny_vertices(self, phenotype: torch.Tensor, theta: torch.Tensor | None) -> torch.Tensor:
        """``(V, 3)`` vertices in Anny's frame (z up, metres) of ``phenotype`` ``(6,)`` in pose
        ``theta`` ``(D,)`` (None: the rest pose)."""
        return self.batch_anny_vertices(phenotype[None], None if theta is None else theta[None])[0]

    def batch_anny_vertices(self, phenotype: torch.Tensor, theta: torch.Tensor | None) -> torch.Tensor:
        """``(B, V, 3)`` Anny-frame vertices of ``B`` bodies in one forward pass: ``phenotype`` ``(B, 6)``
        in poses ``theta`` ``(B, D)`` (None: the rest pose)."""
        import roma

        anny = self.model.model
        params = torch.eye(4).repeat(phenotype.shape[0], anny.bone_count, 1, 1)
        if theta is not None:
            rot = roma.rotvec_to_rotmat(torch.einsum("skd,bd->bsk", self.dof_axes, theta))  # (B, B_sel, 3, 3)
            full = torch.nn.functional.pad(rot, (0, 1, 0, 1))
            full[..., 3, 3] = 1.0
            params[:, self.bone_index] = full
        pheno = {k: phenotype[:, i].clamp(0.0, 1.0) for i, k in enumerate(PHENOTYPES)}
        return anny(pose_parameters=params, phenotype_kwargs=pheno)["vertices"]

    def place(self, anny_verts: torch.Tensor, p: Params) -> torch.Tensor:
        """``(V, 3)`` Anny-frame vertices -> camera frame by the similarity of ``p``."""
        import roma

        rot = roma.rotvec_to_rotmat(p.rotation) @ self.to_camera
        return torch.exp(p.log_scale) * (anny_verts - self.centre) @ rot.T + p.translation

    def camera_vertices(self, p: Params) -> torch.Tensor:
        """``(V, 3)`` camera-frame vertices of the body ``p``."""
        return self.place(self.anny_vertices(p.phenotype, p.theta), p)

    def limit_excess(self, theta: torch.Tensor) -> torch.Tensor:
        """``(D,)`` radians by which each angle lies outside its limits (0 inside)."""
        return torch.relu(theta - self.hi) + torch.relu(self.lo - theta)

    def rest_y_up(self, p: Params) -> np.ndarray:
        """``(V, 3) float64`` rest-pose vertices of ``p``'s phenotype, y up, facing +z, metres times
        the fitted scale, about Anny's origin (near the hips)."""
        with torch.no_grad():
            v = self.anny_vertices(p.phenotype, None) * torch.exp(p.log_scale)
        return anny_to_y_up(v.double().numpy())

    def pose_dict(self, theta: torch.Tensor) -> dict[str, list[float]]:
        """``{bone: rotation vector [3]}`` (Anny's rest axes, as :func:`sample_pose` writes poses)."""
        rv = self.bone_rotvecs(theta.detach()).numpy()
        return {b: [float(x) for x in rv[i]] for i, b in enumerate(self.bones)}
