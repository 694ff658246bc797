"""The non-rigid chain: visible points -> canonical-pose points (canonical task) -> completion.

The canonical checkpoint was trained on the orthographic, normalised depth images of
:mod:`lit3d.render.depth` (unit bounding box, camera at distance 2, depth in [0.1, 1], near =
1). Here the visible points are put into that frame (centred on their bounding box, longest
side 1, seen from the input camera), splatted into an ``S x S`` depth image and mask
(``S`` = the net's ``image_size``), mapped by the net to the canonical depth and mask, and
back-projected with :func:`lit3d.render.depth.depth_to_points`. The canonical points are
returned in the input camera's frame at the visible points' position and size, so the
completed canonical shape sits where the posed subject was.

What it cannot do: the depth extent of the posed subject is only the visible one (so the
normalisation differs from training by how deep the hidden half is), and a perspective image
is treated as orthographic after back-projection.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lit3d.reconstruct.depth_io import InputError
from lit3d.reconstruct.pipeline import load_task
from lit3d.render.depth import CAMERA_DISTANCE, DEPTH_FAR, DEPTH_NEAR, FG_MIN, ORTHO_MAG, depth_to_points

FLIP = np.array([1.0, -1.0, -1.0])  # camera frame (y down, z forward) <-> GL (y up, z back)


@dataclass
class CanonicalMapper:
    """A loaded canonical-task checkpoint (see the module doc)."""
    task: object
    image_size: int
    path: str
    device: str

    def depth_image(self, points_gl: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Normalised GL points ``(N, 3)`` -> ``(S, S) float32`` normalised depth and ``(S, S) bool`` mask."""
        from scipy import ndimage


        s = self.image_size
        col = np.floor((points_gl[:, 0] / ORTHO_MAG + 1) / 2 * s).astype(int)
        row = np.floor((1 - points_gl[:, 1] / ORTHO_MAG) / 2 * s).astype(int)
        dist = CAMERA_DISTANCE - points_gl[:, 2]
        value = np.clip(1 - (1 - FG_MIN) * (dist - DEPTH_NEAR) / (DEPTH_FAR - DEPTH_NEAR), FG_MIN, 1)
        ok = (col >= 0) & (col < s) & (row >= 0) & (row < s)
        depth = np.zeros((s, s), dtype=np.float64)
        np.maximum.at(depth, (row[ok], col[ok]), value[ok])  # nearest point wins (larger = nearer)
        # close the gaps between splatted samples: empty pixels surrounded by samples take the local max
        filled = ndimage.grey_closing(depth, size=3)
        mask = ndimage.binary_closing(depth > 0, iterations=1) | (depth > 0)
        depth = np.where(depth > 0, depth, np.where(mask, filled, 0.0))
        return depth.astype(np.float32), mask & (depth > 0)

    def predict(self, depth: np.ndarray, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The net on one image: ``(S, S)`` normalised depth and mask -> canonical ``(S, S) float32``
        depth and ``(S, S) bool`` mask (probability above 0.5 and depth above 0)."""
        import torch

        d = torch.from_numpy(np.asarray(depth, np.float32))[None, None].to(self.device)
        m = torch.from_numpy(np.asarray(mask, np.float32))[None, None].to(self.device)
        with torch.inference_mode():
            out = self.task(d, m)
        cd = out.depth[0, 0].float().cpu().numpy()
        return cd, (out.mask[0, 0].float().cpu().numpy() > 0.5) & (cd > 0)

    def map_points(self, points: np.ndarray, label: str) -> tuple[np.ndarray, dict]:
        """``(N, 3)`` camera-frame visible points -> ``(M, 3)`` canonical-pose points (same frame), info."""
        gl = points * FLIP
        lo, hi = gl.min(0), gl.max(0)
        centre, scale = (lo + hi) / 2, 1.0 / max(float((hi - lo).max()), 1e-9)
        depth, mask = self.depth_image((gl - centre) * scale)
        cd, cm = self.predict(depth, mask)
        canon = depth_to_points(cd, cm)
        if len(canon) < 10:
            raise InputError(f"{label}: the canonical network predicts an empty canonical form "
                             f"({len(canon)} pixels)")
        info = {"checkpoint": self.path, "image_size": self.image_size, "input_pixels": int(mask.sum()),
                "canonical_pixels": int(cm.sum())}
        return (canon / scale + centre) * FLIP, info


def load_canonical(path: str, device: str = "cpu") -> CanonicalMapper:
    """Load a canonical-task checkpoint (``weights_only=True``) as a :class:`CanonicalMapper`."""
    task, _ = load_task(path, device, "canonical")
    net = dict(task.hparams.get("net") or {})
    return CanonicalMapper(task, int(net.get("image_size", 128)), str(path), device)
