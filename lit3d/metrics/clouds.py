"""Chamfer distance, F-score and normal consistency of batched point clouds, each with its
convention named in its arguments.

Inputs are torch tensors ``x (B, N, 3)`` (e.g. the prediction's surface samples) and ``y (B, M, 3)``
(the target's), on any device (the nearest neighbours run there, :mod:`lit3d.metrics.nearest`),
optionally ragged (``x_lengths``, ``y_lengths``: ``(B,)`` real points per row). With
``d_xy(i)`` the distance from ``x_i`` to its nearest ``y`` point and ``d_yx(j)`` the reverse:

- **Chamfer distance**, :func:`chamfer_distance`: per direction the mean of ``d`` (``squared=False``)
  or of ``d^2`` (``squared=True``) over the real points; the two directions then averaged
  (``directions="mean"``) or added (``directions="sum"``). The presets (``convention=``):

  ======================  ==========  =============  =====================================================
  convention              squared     directions     used by
  ======================  ==========  =============  =====================================================
  ``"l1"`` (default)      no          mean (halved)  lit3d's tables; Occupancy Networks' "Chamfer-L1";
                                                     PCN / GRNet "CD-L1"; Open3D's mean point distances
  ``"pytorch3d"``         yes         sum            ``pytorch3d.loss.chamfer_distance`` (its defaults);
                                                     GRNet "CD-L2"
  ======================  ==========  =============  =====================================================

- **F-score** at a distance threshold ``tau``, :func:`f_score`: precision ``P = mean(d_xy <= tau)``,
  recall ``R = mean(d_yx <= tau)``, ``F = 2PR / (P + R)`` (0 when ``P + R = 0``). ``threshold_mode``
  says what ``threshold`` is: ``"absolute"`` (``tau = threshold``, in the clouds' units),
  ``"bbox_diagonal"`` (``tau = threshold x`` the diagonal of ``y``'s bounding box, per row; lit3d's
  "F-score@1%"), ``"volume_side"`` (``tau = threshold x side``, the side of the reconstructed volume:
  Tatarchenko et al. 2019; ``side=1`` in lit3d's unit grid frame).
- **Normal consistency**, :func:`normal_consistency`: the mean over both directions of
  ``|n . n_nn|`` between each point's unit normal and its nearest neighbour's (``oriented=False``,
  Occupancy Networks'; 1 = parallel), or of the signed cosine (``oriented=True``).

``reduction`` reduces the per-row values over the batch: ``"mean"`` (default) or ``"sum"`` to a 0-d
tensor, ``"none"`` keeps ``(B,)`` (``(B, T)`` for ``T`` F-score thresholds).
"""
from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import torch

from lit3d.metrics.nearest import cloud_lengths, nearest, valid_mask


class ChamferConvention(NamedTuple):
    """``squared``: mean of squared distances per direction; ``directions``: ``"mean"`` or ``"sum"`` of the two."""

    squared: bool
    directions: str


CHAMFER_CONVENTIONS = {
    "l1": ChamferConvention(squared=False, directions="mean"),
    "pytorch3d": ChamferConvention(squared=True, directions="sum"),
}
THRESHOLD_MODES = ("absolute", "bbox_diagonal", "volume_side")
REDUCTIONS = ("mean", "sum", "none")


def _reduce(values: torch.Tensor, reduction: str) -> torch.Tensor:
    if reduction == "mean":
        return values.mean(0)
    if reduction == "sum":
        return values.sum(0)
    if reduction == "none":
        return values
    raise ValueError(f"reduction={reduction!r}: expected one of {REDUCTIONS}")


def masked_mean(values: torch.Tensor, lengths: torch.Tensor | None) -> torch.Tensor:
    """Mean of ``values (B, N)`` over each row's first ``lengths (B,)`` entries (all when None): ``(B,)``."""
    if lengths is None:
        return values.mean(-1)
    mask = valid_mask(lengths, values.shape[-1])
    return (values * mask).sum(-1) / lengths.to(values.dtype)


def chamfer_from_distances(d_xy: torch.Tensor, d_yx: torch.Tensor, x_lengths: torch.Tensor | None = None,
                           y_lengths: torch.Tensor | None = None, *, squared: bool,
                           directions: str) -> torch.Tensor:
    """Chamfer distance ``(B,)`` from the nearest distances ``d_xy (B, N)`` and ``d_yx (B, M)`` (module doc)."""
    if directions not in ("mean", "sum"):
        raise ValueError(f"directions={directions!r}: expected 'mean' or 'sum'")
    a = masked_mean(d_xy.square() if squared else d_xy, x_lengths)
    b = masked_mean(d_yx.square() if squared else d_yx, y_lengths)
    return a + b if directions == "sum" else 0.5 * (a + b)


def precision_recall_fscore(d_xy: torch.Tensor, d_yx: torch.Tensor, tau: torch.Tensor,
                            x_lengths: torch.Tensor | None = None, y_lengths: torch.Tensor | None = None,
                            ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """``(precision, recall, fscore)``, each ``(B, T)``, at absolute thresholds ``tau`` (``(T,)`` or
    ``(B, T)``) from the nearest distances ``d_xy (B, N)`` and ``d_yx (B, M)``; F 0 where P + R = 0."""
    tau = torch.as_tensor(tau, dtype=d_xy.dtype, device=d_xy.device)
    tau = tau.expand(d_xy.shape[0], -1) if tau.dim() == 1 else tau  # (B, T)
    hits_x = (d_xy[:, :, None] <= tau[:, None, :]).to(d_xy.dtype)  # (B, N, T)
    hits_y = (d_yx[:, :, None] <= tau[:, None, :]).to(d_xy.dtype)
    precision = hits_x.mean(1) if x_lengths is None else _row_mean(hits_x, x_lengths)
    recall = hits_y.mean(1) if y_lengths is None else _row_mean(hits_y, y_lengths)
    denom = precision + recall
    fscore = torch.where(denom > 0, 2 * precision * recall / torch.where(denom > 0, denom, 1), 0)
    return precision, recall, fscore


def _row_mean(hits: torch.Tensor, lengths: torch.Tensor) -> torch.Tensor:
    """Mean of ``hits (B, N, T)`` over each row's first ``lengths`` points: ``(B, T)``."""
    mask = valid_mask(lengths, hits.shape[1])[:, :, None]
    return (hits * mask).sum(1) / lengths.to(hits.dtype)[:, None]


def bbox_diagonal(points: torch.Tensor, lengths: torch.Tensor | None = None) -> torch.Tensor:
    """Length of each row's axis-aligned bounding-box diagonal, ``points (B, N, 3)`` -> ``(B,)``."""
    if lengths is None:
        lo, hi = points.amin(1), points.amax(1)
    else:
        pad = ~valid_mask(lengths, points.shape[1])[:, :, None]
        lo = points.masked_fill(pad, float("inf")).amin(1)
        hi = points.masked_fill(pad, float("-inf")).amax(1)
    return torch.linalg.vector_norm(hi - lo, dim=-1)


def absolute_thresholds(threshold: float | Sequence[float] | torch.Tensor, y: torch.Tensor,
                        y_lengths: torch.Tensor | None = None, *, threshold_mode: str,
                        side: float = 1.0) -> torch.Tensor:
    """The distance thresholds ``(B, T)`` that ``threshold`` (``T`` numbers, or one) means under
    ``threshold_mode`` for targets ``y (B, M, 3)`` (module doc)."""
    t = torch.as_tensor(threshold, dtype=y.dtype, device=y.device).reshape(1, -1)
    if threshold_mode == "absolute":
        scale = torch.ones(y.shape[0], 1, dtype=y.dtype, device=y.device)
    elif threshold_mode == "bbox_diagonal":
        scale = bbox_diagonal(y, y_lengths)[:, None]
    elif threshold_mode == "volume_side":
        scale = torch.full((y.shape[0], 1), float(side), dtype=y.dtype, device=y.device)
    else:
        raise ValueError(f"threshold_mode={threshold_mode!r}: expected one of {THRESHOLD_MODES}")
    return t * scale


def _both_ways(x, y, x_lengths, y_lengths, backend):
    xl, yl = cloud_lengths(x, x_lengths, "x"), cloud_lengths(y, y_lengths, "y")
    fwd = nearest(x, y, xl, yl, backend=backend)
    bwd = nearest(y.to(x.dtype), x, yl, xl, backend=backend)
    return fwd, bwd, (None if x_lengths is None else xl), (None if y_lengths is None else yl)


def chamfer_distance(x: torch.Tensor, y: torch.Tensor, *, x_lengths: torch.Tensor | None = None,
                     y_lengths: torch.Tensor | None = None, convention: str = "l1", squared: bool | None = None,
                     directions: str | None = None, reduction: str = "mean", backend: str = "auto") -> torch.Tensor:
    """Chamfer distance between ``x (B, N, 3)`` and ``y (B, M, 3)`` (module doc), differentiable.

    Args:
        convention: ``"l1"`` (mean unsquared distances, the two directions averaged: lit3d's
            "Chamfer-L1") or ``"pytorch3d"`` (mean squared distances, the two directions added).
        squared, directions: override the preset's (``directions``: ``"mean"`` or ``"sum"``).
        reduction: over the batch, ``"mean"``, ``"sum"`` or ``"none"`` (``(B,)``).
        backend: nearest-neighbour backend of :func:`lit3d.metrics.nearest.nearest`.
    """
    if convention not in CHAMFER_CONVENTIONS:
        raise ValueError(f"convention={convention!r}: expected one of {sorted(CHAMFER_CONVENTIONS)}")
    preset = CHAMFER_CONVENTIONS[convention]
    fwd, bwd, xl, yl = _both_ways(x, y, x_lengths, y_lengths, backend)
    values = chamfer_from_distances(fwd.distance, bwd.distance, xl, yl,
                                    squared=preset.squared if squared is None else bool(squared),
                                    directions=preset.directions if directions is None else directions)
    return _reduce(values, reduction)


def f_score(x: torch.Tensor, y: torch.Tensor, threshold: float | Sequence[float] | torch.Tensor, *,
            threshold_mode: str = "absolute", side: float = 1.0, x_lengths: torch.Tensor | None = None,
            y_lengths: torch.Tensor | None = None, reduction: str = "mean", backend: str = "auto") -> torch.Tensor:
    """F-score of prediction ``x (B, N, 3)`` against target ``y (B, M, 3)`` at ``threshold`` (module doc).

    Args:
        threshold: one number (result ``(B,)`` before reduction) or ``T`` numbers (``(B, T)``).
        threshold_mode: ``"absolute"`` (a distance), ``"bbox_diagonal"`` (a share of ``y``'s bounding-box
            diagonal: lit3d's tables) or ``"volume_side"`` (a share of ``side``: Tatarchenko et al. 2019).
        side: the volume's side for ``"volume_side"`` (1 in lit3d's unit grid frame).
        reduction: over the batch, ``"mean"``, ``"sum"`` or ``"none"``.
    """
    fwd, bwd, xl, yl = _both_ways(x, y, x_lengths, y_lengths, backend)
    tau = absolute_thresholds(threshold, y, yl, threshold_mode=threshold_mode, side=side)
    values = precision_recall_fscore(fwd.distance, bwd.distance, tau, xl, yl)[2]
    if torch.as_tensor(threshold).dim() == 0:
        values = values[:, 0]
    return _reduce(values, reduction)


def consistency_from_neighbours(nx: torch.Tensor, ny: torch.Tensor, index_xy: torch.Tensor,
                                index_yx: torch.Tensor, x_lengths: torch.Tensor | None = None,
                                y_lengths: torch.Tensor | None = None, *, oriented: bool = False) -> torch.Tensor:
    """Normal consistency ``(B,)`` of unit normals ``nx (B, N, 3)``, ``ny (B, M, 3)`` given the nearest
    indices ``index_xy (B, N)`` into ``y`` and ``index_yx (B, M)`` into ``x`` (module doc)."""
    ny_at_x = torch.gather(ny, 1, index_xy[..., None].expand(-1, -1, 3))
    nx_at_y = torch.gather(nx, 1, index_yx[..., None].expand(-1, -1, 3))
    cos_x, cos_y = (nx * ny_at_x).sum(-1), (ny * nx_at_y).sum(-1)
    if not oriented:
        cos_x, cos_y = cos_x.abs(), cos_y.abs()
    return 0.5 * (masked_mean(cos_x, x_lengths) + masked_mean(cos_y, y_lengths))


def normal_consistency(x: torch.Tensor, nx: torch.Tensor, y: torch.Tensor, ny: torch.Tensor, *,
                       x_lengths: torch.Tensor | None = None, y_lengths: torch.Tensor | None = None,
                       oriented: bool = False, reduction: str = "mean", backend: str = "auto") -> torch.Tensor:
    """Normal consistency of ``x (B, N, 3)`` with normals ``nx (B, N, 3)`` against ``y (B, M, 3)``, ``ny``
    (module doc; the normals are normalised first). ``oriented=False``: ``|cos|`` (Occupancy Networks)."""
    if nx.shape != x.shape or ny.shape != y.shape:
        raise ValueError(f"normals of shapes {tuple(nx.shape)}, {tuple(ny.shape)} for points of shapes "
                         f"{tuple(x.shape)}, {tuple(y.shape)}")
    fwd, bwd, xl, yl = _both_ways(x, y, x_lengths, y_lengths, backend)
    nx = torch.nn.functional.normalize(nx.to(x.dtype), dim=-1)
    ny = torch.nn.functional.normalize(ny.to(x.dtype), dim=-1)
    values = consistency_from_neighbours(nx, ny, fwd.index, bwd.index, xl, yl, oriented=oriented)
    return _reduce(values, reduction)


__all__ = ["CHAMFER_CONVENTIONS", "THRESHOLD_MODES", "ChamferConvention", "absolute_thresholds", "bbox_diagonal",
           "chamfer_distance", "chamfer_from_distances", "consistency_from_neighbours", "f_score", "masked_mean",
           "normal_consistency", "precision_recall_fscore"]
