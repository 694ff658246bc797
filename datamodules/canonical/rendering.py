"""Rendering of one subject's cache file: every pose's depth images and, for pairs whose meshes
correspond, the flow and visibility targets of the warp head (:mod:`datamodules.canonical.flow`).

Every shape is centred on its bounding-box centre and scaled so that its longest side is 1
(``scale_mode="shape"``) or by the subject's canonical scale (``scale_mode="subject"``), turned by
its view mode's azimuth plus each configured azimuth, and rendered by the depth camera
(:func:`lit3d.render.depth.render_depth`).

Arrays of a subject file (``S = image_size``; layout read by :mod:`datamodules.canonical.images`):
    depth_<p>_<v>  (S, S) float16       mask_<p>_<v>  packed bits of (S, S) bool
    flow_<p>_<v>   (2, S, S) float16    vis_<p>_<v>   packed bits of (S, S) bool   (``flow_targets``;
                   only for poses whose mesh corresponds to the canonical one)
    poses (str), skipped (str)
"""
from __future__ import annotations

import logging

import numpy as np

from datamodules.cache import DataError
from datamodules.canonical.flow import flow_targets
from datamodules.canonical.images import depth_image_problem
from datamodules.canonical.settings import RenderSettings
from lit3d.geometry.normalise import bounding_frame
from lit3d.geometry.broadside import base_azimuth
from lit3d.render.depth import render_depth, rotate_y

log = logging.getLogger("lit3d")


class PairRenderer:
    """Renders the subjects of ``source`` (:mod:`datamodules.canonical.sources`) as ``render`` says
    (:class:`~datamodules.canonical.settings.RenderSettings`: azimuths, view and scale mode, flow targets)
    at ``image_size``; ``skip_bad``: a bad pose is dropped with a warning instead of raising."""

    def __init__(self, source, render: RenderSettings, image_size: int, skip_bad: bool = False):
        self.source, self.render, self.image_size, self.skip_bad = source, render, int(image_size), bool(skip_bad)

    def raw_mesh(self, subject: str, pose) -> tuple[np.ndarray, np.ndarray]:
        """``(V, 3)``, ``(F, 3)`` of (subject, pose) as the source gives it (``pose="canonical"`` ok)."""
        src = self.source
        return src.mesh(subject, src.canonical_pose(subject) if pose == "canonical" else pose)

    def frame(self, subject: str, v: np.ndarray) -> tuple[np.ndarray, float]:
        """Centre ``(3,)`` and scale that normalise raw vertices ``v`` of ``subject`` (``scale_mode``:
        ``subject`` takes the scale of the subject's canonical mesh)."""
        scale = bounding_frame(self.raw_mesh(subject, "canonical")[0])[1] if self.render.scale_mode == "subject" else None
        return bounding_frame(v, scale)

    def normalise(self, subject: str, v: np.ndarray) -> np.ndarray:
        """Raw ``(V, 3)`` vertices of ``subject`` centred and scaled by ``scale_mode``."""
        centre, scale = self.frame(subject, v)
        return (np.asarray(v, np.float64) - centre) * scale

    def normalized_mesh(self, subject: str, pose) -> tuple[np.ndarray, np.ndarray]:
        """The mesh of (subject, pose) centred and scaled as it is rendered."""
        v, f = self.raw_mesh(subject, pose)
        return self.normalise(subject, v), f

    def view_azimuths(self, v: np.ndarray, f: np.ndarray) -> list[float]:
        """Azimuth of every configured view of normalised vertices ``v``: view mode's base + offset."""
        base = base_azimuth(v, f, self.render.view_mode)
        return [base + float(az) for az in self.render.azimuths]

    def render_views(self, subject: str, v: np.ndarray, f: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
        """(depth, mask) ``(S, S)`` of every azimuth of raw mesh ``v, f``; DataError for a bad image."""
        return self._render_normalised(self.normalise(subject, v), f)[0]

    def _render_normalised(self, v: np.ndarray, f: np.ndarray) -> tuple[list[tuple[np.ndarray, np.ndarray]], list[float]]:
        """(depth, mask) ``(S, S)`` of every view of normalised vertices ``v``, and the views' azimuths;
        DataError for a bad image."""
        size, azimuths, out = self.image_size, self.view_azimuths(v, f), []
        for vi, az in enumerate(azimuths):
            d, m = render_depth(v, f, size, az)
            problem = depth_image_problem(d, m, size)
            if problem:
                raise DataError(f"view {vi}: rendered {problem} (mesh outside the view?)")
            out.append((d, m))
        return out, azimuths

    def canonical_turned(self, subject: str, view: int, turn_deg: float) -> tuple[np.ndarray, np.ndarray]:
        """The subject's canonical depth ``(S, S)`` float32 and mask ``(S, S)`` bool seen from view ``view``
        turned by a further ``turn_deg`` degrees about the vertical (a jittered camera)."""
        v, f = self.normalized_mesh(subject, "canonical")
        return render_depth(v, f, self.image_size, self.view_azimuths(v, f)[int(view)] + float(turn_deg))

    def _pose_arrays(self, subject: str, pose, canon: dict | None) -> dict[str, np.ndarray]:
        """Depth (float16) and packed mask of every view of one pose, with flow and visibility when
        ``canon`` (the canonical pose's normalised vertices, view azimuths and images) is given and
        the source has a correspondence for this pose; DataError for a bad image."""
        v, f = self.raw_mesh(subject, pose)
        centre, scale = self.frame(subject, v)
        views, posed_az = self._render_normalised((np.asarray(v, np.float64) - centre) * scale, f)
        out = {}
        for vi, (d, m) in enumerate(views):
            out[f"depth_{pose}_{vi}"] = d.astype(np.float16)
            out[f"mask_{pose}_{vi}"] = np.packbits(m)
        corr = None if canon is None else self.source.correspondence(subject, pose, canon["raw"], canon["faces"], v, f)
        if corr is None:
            return out
        corr = (np.asarray(corr, np.float64) - centre) * scale  # the posed mesh's own frame
        for vi, (d, m) in enumerate(views):
            cd, cm = canon["views"][vi]
            canon_v, posed_v = rotate_y(canon["verts"], canon["azimuths"][vi]), rotate_y(corr, posed_az[vi])
            flow, vis = flow_targets(canon_v, posed_v, cd, cm, d, m)
            out[f"flow_{pose}_{vi}"] = flow.astype(np.float16)
            out[f"vis_{pose}_{vi}"] = np.packbits(vis)
        return out

    def render_subject(self, subject: str) -> dict[str, np.ndarray]:
        """Arrays of one subject's cache file; ``skipped`` lists the poses dropped by ``skip_bad``."""
        arrays: dict[str, np.ndarray] = {}
        canon = None
        try:
            cv, cf = self.raw_mesh(subject, "canonical")
            verts = self.normalise(subject, cv)
            views, azimuths = self._render_normalised(verts, cf)
        except Exception as exc:
            raise DataError(f"{subject} pose canonical: {exc}") from exc
        for vi, (d, m) in enumerate(views):
            arrays[f"depth_canonical_{vi}"] = d.astype(np.float16)
            arrays[f"mask_canonical_{vi}"] = np.packbits(m)
        if self.render.flow_targets:
            canon = {"raw": cv, "faces": cf, "verts": verts, "azimuths": azimuths, "views": views}
        poses, skipped = list(self.source.poses(subject)), []
        for p in poses:
            try:
                arrays.update(self._pose_arrays(subject, p, canon))
            except Exception as exc:
                msg = f"{subject} pose {p}: {exc}"
                if not self.skip_bad:
                    raise DataError(msg) from exc
                log.warning("skipping: %s", msg)
                skipped.append(msg)
        kept = [p for p in poses if f"depth_{p}_0" in arrays]
        arrays["poses"] = np.array([str(p) for p in kept])
        arrays["skipped"] = np.array(skipped, dtype=str)
        return arrays
