"""What a body fit gives (:func:`fit_outputs`): the posed mesh in the camera frame, the same mesh
in the rest pose, its canonical depth image, the fit's quality and the parameters as JSON.

- **posed mesh** ``(V, 3)`` camera frame (x right, y down, z forward), metres: overlays the input;
- **canonical mesh** ``(V, 3)``: the fitted phenotype in Anny's rest pose (the canonical pose of
  the Anny data source), y up, facing +z, metres times the fitted scale; same faces;
- **canonical depth** ``(S, S) float32`` in [0, 1] (0 = background), ``S = 128``: rendered as the
  canonical task renders its targets for the Anny source (``conf/data/anny.yaml``:
  ``scale_mode=shape``, ``view_mode=fixed``, ``azimuths=[0]``): the mesh centred on its bounding
  box, longest side 1 (:func:`lit3d.geometry.normalise.normalise_vertices`), then
  :func:`lit3d.render.depth.render_depth` at azimuth 0;
- **quality**: median and 90th percentile of the point-to-surface distance over every foreground
  point (the fit's own measure: nearest front-facing vertex, point-to-vertex/plane mix), the
  silhouette IoU of the fitted mesh rendered through the input camera against the foreground mask,
  and ``poor_fit`` with its reasons (:data:`POOR_MEDIAN_M`, :data:`POOR_IOU`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from lit3d.body_fit.fit import FitResult
from lit3d.body_fit.model import DOFS, PHENOTYPES, Body
from lit3d.body_fit.depth_points import Observation
from lit3d.body_fit.surface import point_to_surface
from lit3d.geometry.normalise import normalise_vertices
from lit3d.render.camera import render_pinhole_depth
from lit3d.render.depth import render_depth

CANONICAL_SIZE = 128  # the Anny data source's image_size (conf/data/anny.yaml)
POOR_MEDIAN_M = 0.025  # a median point-to-surface distance above this (metres) is a poor fit
POOR_IOU = 0.75        # a silhouette IoU below this is a poor fit


@dataclass
class BodyOutputs:
    """See the module doc; ``faces`` ``(F, 3) int64`` are shared by both meshes."""

    posed: np.ndarray            # (V, 3) float64 camera frame, metres
    canonical: np.ndarray        # (V, 3) float64 y up, metres
    faces: np.ndarray            # (F, 3) int64
    canonical_depth: np.ndarray  # (S, S) float32, 0 = background
    rendered_mask: np.ndarray    # (H, W) bool: the posed mesh seen by the input camera
    quality: dict
    params: dict


def canonical_depth(verts_y_up: np.ndarray, faces: np.ndarray, size: int = CANONICAL_SIZE) -> np.ndarray:
    """``(S, S) float32`` canonical-task depth image of a y-up mesh (see the module doc)."""
    v, _ = normalise_vertices(verts_y_up)
    return render_depth(v, faces, size, 0.0)[0]


def render_mask(verts: np.ndarray, faces: np.ndarray, obs: Observation) -> np.ndarray:
    """``(H, W) bool``: pixels of the input camera covered by camera-frame mesh ``verts``."""
    gl = np.asarray(verts, np.float64) * np.array([1.0, -1.0, -1.0])  # camera frame -> GL
    h, w = obs.shape
    # the renderer's principal point addresses the pixel corner, ours the pixel centre
    depth = render_pinhole_depth(gl, faces, np.eye(4), w, h, obs.fx, obs.fy, obs.cx + 0.5, obs.cy + 0.5,
                                 znear=0.05, zfar=100.0)
    return depth > 0


def fit_quality(body: Body, fit: FitResult, obs: Observation, rendered: np.ndarray) -> dict:
    """Point-to-surface statistics, silhouette IoU and the ``poor_fit`` verdict (module doc)."""
    with torch.no_grad():
        d = point_to_surface(torch.from_numpy(fit.vertices).float(), body.faces, torch.from_numpy(obs.points).float(),
                             1.0, body.incidence).numpy()
    inter, union = int((rendered & obs.mask).sum()), int((rendered | obs.mask).sum())
    iou = inter / max(union, 1)
    median = float(np.median(d))
    reasons = []
    if median > POOR_MEDIAN_M:
        reasons.append(f"median point-to-surface distance {100 * median:.1f} cm > {100 * POOR_MEDIAN_M:.1f} cm")
    if iou < POOR_IOU:
        reasons.append(f"silhouette IoU {iou:.2f} < {POOR_IOU:.2f}")
    return {"median_point_to_surface_m": median, "p90_point_to_surface_m": float(np.percentile(d, 90)),
            "point_to_surface_measure": "nearest front-facing vertex (point-to-vertex), all foreground points",
            "silhouette_iou": iou, "poor_fit": bool(reasons), "poor_fit_reasons": reasons,
            "thresholds": {"median_point_to_surface_m": POOR_MEDIAN_M, "silhouette_iou": POOR_IOU}}


def fit_params(body: Body, fit: FitResult) -> dict:
    """The fitted parameters, JSON-ready (see :mod:`lit3d.body_fit.model` for their meaning)."""
    p = fit.params
    return {
        "phenotype": {k: float(v) for k, v in zip(PHENOTYPES, p.phenotype.tolist())},
        "pose_rotvec_anny_rest_axes": body.pose_dict(p.theta),
        "joint_angles": [{"bone": d.bone, "axis": list(d.axis), "angle_rad": float(a), "limits": [d.lo, d.hi]}
                         for d, a in zip(DOFS, p.theta.tolist())],
        "rotation_rotvec_camera": [float(x) for x in p.rotation.tolist()],
        "translation_m_camera": [float(x) for x in p.translation.tolist()],
        "scale": float(torch.exp(p.log_scale)),
        "body_centre_anny": [float(x) for x in body.centre.tolist()],
        "model": "anny (phenotypes: default 6)",
        "formula": "camera = scale * R(rotation) @ C @ (v_anny - body_centre_anny) + translation, "
                   "C = [[1,0,0],[0,0,-1],[0,1,0]]",
        "iterations": fit.iterations, "fit_seconds": fit.seconds, "final_loss_terms": fit.terms,
    }


def fit_outputs(body: Body, fit: FitResult, obs: Observation, size: int = CANONICAL_SIZE) -> BodyOutputs:
    """Everything written for one fit (see the module doc)."""
    rest = body.rest_y_up(fit.params)
    rendered = render_mask(fit.vertices, body.faces, obs)
    return BodyOutputs(fit.vertices, rest, body.faces, canonical_depth(rest, body.faces, size), rendered,
                       fit_quality(body, fit, obs, rendered), fit_params(body, fit))
