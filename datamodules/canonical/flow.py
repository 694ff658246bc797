"""Flow and visibility targets of a posed/canonical pair whose meshes correspond point by point.

For every pixel of the canonical image the backward flow says where the same surface point lies in
the posed image, and the visibility says whether that point is seen there (not hidden by another part
of the posed body, not turned away). The warp head of the canonical net learns them
(:mod:`lit3d.canonical.warp`): the canonical image is the posed image's pixels moved, where visible.

How they are made (no extra rendering): the canonical mesh's vertices are projected by the depth
camera (:func:`lit3d.render.depth.project_points`) and kept where the canonical depth image shows
them (z-test, ``tol``); the same vertices' posed positions (``corr``: Anny, TOSCA and Sumner meshes
share their vertex order, as FAUST's original registrations do, not the remeshed ``faust_a``; the
procedural figures are skinned, :func:`skinned_canonical`) are
projected too and z-tested against the posed depth image. Each canonical foreground pixel takes the
inverse-distance mean of the displacements of its ``k`` nearest canonical-visible vertices; it is
visible when most of their weight is seen in the posed image and the nearest lies within ``radius``
pixels.

Arrays (``S = image_size``):
    flow  (2, S, S) float32  (dx, dy) in pixels: canonical pixel (x, y) <- posed pixel (x + dx, y + dy);
                             0 outside the canonical mask
    vis   (S, S) bool        the canonical pixel's surface point is seen in the posed image
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from datamodules.canonical.figures import capsule_bones, capsules, joint_frames
from lit3d.render.depth import project_points, rotate_y

DEPTH_TOL = 0.03   # normalised depth units (0.9 per unit of the unit box): front vs back surfaces
K_NEAREST = 4
RADIUS_PX = 2.0


def _seen(col: np.ndarray, row: np.ndarray, depth: np.ndarray, image: np.ndarray, mask: np.ndarray,
          tol: float) -> np.ndarray:
    """``(N,)`` bool: the projected points (pixel coordinates, normalised depth) are the surface that
    ``image`` / ``mask`` ``(S, S)`` show at their nearest pixel."""
    size = image.shape[0]
    ci, ri = np.rint(col).astype(np.int64), np.rint(row).astype(np.int64)
    ok = (ci >= 0) & (ci < size) & (ri >= 0) & (ri < size)
    out = np.zeros(len(col), bool)
    c, r = ci[ok], ri[ok]
    out[ok] = (mask[r, c] > 0.5) & (np.abs(image[r, c] - depth[ok]) < tol)
    return out


def flow_targets(canon_verts: np.ndarray, corr: np.ndarray, canon_depth: np.ndarray, canon_mask: np.ndarray,
                 posed_depth: np.ndarray, posed_mask: np.ndarray, tol: float = DEPTH_TOL, k: int = K_NEAREST,
                 radius: float = RADIUS_PX) -> tuple[np.ndarray, np.ndarray]:
    """Backward flow ``(2, S, S)`` float32 and visibility ``(S, S)`` bool (module docstring).

    ``canon_verts`` ``(V, 3)``: the canonical mesh as rendered (normalised, turned to the view);
    ``corr`` ``(V, 3)``: the same vertices' positions in the posed mesh as rendered; the four images
    ``(S, S)`` are the rendered pair (depth in [0, 1], masks bool or {0, 1})."""
    size = canon_depth.shape[0]
    cc, rc, dc = project_points(canon_verts, size)
    cp, rp, dp = project_points(corr, size)
    keep = _seen(cc, rc, dc, canon_depth, canon_mask, tol)
    flow = np.zeros((2, size, size), np.float32)
    vis = np.zeros((size, size), bool)
    rows, cols = np.nonzero(canon_mask > 0.5)
    if not keep.any() or not len(rows):
        return flow, vis
    seen_posed = _seen(cp[keep], rp[keep], dp[keep], posed_depth, posed_mask, tol).astype(np.float64)
    tree = cKDTree(np.stack([rc[keep], cc[keep]], 1))
    dist, idx = tree.query(np.stack([rows, cols], 1).astype(np.float64), k=min(k, int(keep.sum())))
    dist, idx = dist.reshape(len(rows), -1), idx.reshape(len(rows), -1)
    w = 1.0 / np.maximum(dist, 1e-3)
    w = w / w.sum(1, keepdims=True)
    flow[0, rows, cols] = (w * (cp - cc)[keep][idx]).sum(1)  # each vertex's own displacement, interpolated
    flow[1, rows, cols] = (w * (rp - rc)[keep][idx]).sum(1)
    vis[rows, cols] = ((w * seen_posed[idx]).sum(1) > 0.5) & (dist[:, 0] <= radius)
    return flow, vis


def skinned_canonical(subject, canon_verts: np.ndarray, pose, canon_yaw: float, posed_yaw: float) -> np.ndarray:
    """Posed positions ``(V, 3)`` of a procedural figure's canonical mesh vertices (raw, as
    :func:`datamodules.canonical.figures.figure_mesh` makes them, turned by ``canon_yaw`` degrees): each
    vertex moves rigidly with the bone whose capsule is nearest, then the whole is turned by
    ``posed_yaw`` (the posed mesh's turn)."""
    v = rotate_y(np.asarray(canon_verts, np.float64), -canon_yaw)  # undo figure_mesh's turn
    p0, g0 = joint_frames(subject, None)
    p1, g1 = joint_frames(subject, pose)
    bones = capsule_bones(subject)  # (anchor joint, frame joint) per capsule, in capsules() order
    a, b, ra, rb = capsules(subject, None)
    best, owner = np.full(len(v), np.inf), np.zeros(len(v), np.int64)
    for i in range(len(a)):
        ab = b[i] - a[i]
        l2 = float(ab @ ab)
        t = np.zeros(len(v)) if l2 < 1e-12 else np.clip((v - a[i]) @ ab / l2, 0.0, 1.0)
        d = np.linalg.norm(v - (a[i] + t[:, None] * ab), axis=1) - (ra[i] + t * (rb[i] - ra[i]))
        closer = d < best
        best[closer], owner[closer] = d[closer], i
    out = np.empty_like(v)
    for i, (anchor, frame) in enumerate(bones):
        sel = owner == i
        rot = g1[frame] @ g0[frame].T
        out[sel] = p1[anchor] + (v[sel] - p0[anchor]) @ rot.T
    return rotate_y(out, posed_yaw)
