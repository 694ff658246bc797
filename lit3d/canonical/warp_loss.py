"""The warp head's loss terms (:mod:`lit3d.canonical.warp`), from a net output and a batch.

Batch keys (``datamodules.canonical`` with ``data.render.flow_targets=true``): ``flow`` ``(B, 2, H, W)`` in
pixels, ``vis`` ``(B, 1, H, W)`` (backward, at canonical pixels: the warp head's), ``fflow``, ``fvis``
(forward, at posed pixels: the splat head's, :mod:`lit3d.canonical.splat`), ``has_flow`` ``(B,)`` bool,
``mask``, ``canon_depth``, ``canon_mask`` ``(B, 1, H, W)``. "Foreground" below is that of the flow's own
frame: the canonical mask for the warp head, the posed mask for the splat head. Batches without flow targets
(FAUST) give zero flow and visibility terms.

``flow_on`` says where the flow's end-point distance is paid: ``visible`` (the canonical pixels whose
surface point the posed image shows), ``foreground`` (every canonical foreground pixel: a hidden
point's target lands on the part that hides it, still on the posed body, so the moved mask is right
there even where the depth must come from the fill) or ``image`` (every pixel: on the canonical
background the target leads off the posed body, :func:`escape_flow`, so a posed limb is not read where
the canonical form has none; warp head only; computed for the batch only then).

``vis_on`` says where the visibility is paid: ``foreground`` (the canonical foreground only: the
background's visibility is left to the mask loss) or ``image`` (every pixel, the canonical background
with target 0: there the output takes the fill, whose mask the mask loss drives to 0). Measured on the
demo: with ``foreground`` the head keeps the visibility near 1 everywhere, and a canonical background
pixel whose flow lands inside a posed limb (flat mask, no gradient) keeps that limb where it was posed.
"""
from __future__ import annotations

import numpy as np
import torch
from scipy.ndimage import distance_transform_edt

from lit3d.canonical.losses import depth_gradient_loss, flow_loss, flow_smoothness, visibility_loss
from lit3d.canonical.warp import pixels_to_grid

FLOW_ON = ("visible", "foreground", "image")
VIS_ON = ("foreground", "image")


def check_choices(flow_on: str, vis_on: str) -> None:
    """ValueError naming ``task.warp.flow_on`` or ``task.warp.vis_on`` when it is not one of its choices."""
    for name, value, choices in (("flow_on", flow_on, FLOW_ON), ("vis_on", vis_on, VIS_ON)):
        if value not in choices:
            raise ValueError(f"task.warp.{name} must be one of {choices}, got '{value}'")


def escape_flow(flow: np.ndarray, canon_mask: np.ndarray, posed_mask: np.ndarray) -> np.ndarray:
    """The backward ``flow`` ``(2, S, S)`` (pixels; 0 off the canonical body) with a target on the canonical
    background too: where the posed image shows the body at that pixel (``posed_mask`` ``(S, S)``), the
    displacement to the nearest posed background pixel (a pixel read there shows no body), elsewhere 0
    (also where the posed image has no background at all)."""
    canon, posed = np.asarray(canon_mask) > 0.5, np.asarray(posed_mask) > 0.5
    stale = ~canon & posed
    if not stale.any() or posed.all():  # nothing to leave, or no posed background to leave to
        return flow
    _, (rows, cols) = distance_transform_edt(posed, return_indices=True)
    out = np.array(flow, np.float32, copy=True)
    r, c = np.nonzero(stale)
    out[0, r, c] = cols[r, c] - c
    out[1, r, c] = rows[r, c] - r
    return out


def _escape_targets(target: torch.Tensor, batch: dict) -> torch.Tensor:
    """The backward target flow ``(B, 2, H, W)`` (grid units) with :func:`escape_flow` on each item's
    canonical background (``canon_mask``, ``mask`` ``(B, 1, H, W)``); on the CPU, per item."""
    px = batch["flow"].detach().float().cpu().numpy()
    canon, posed = batch["canon_mask"].detach().cpu().numpy(), batch["mask"].detach().cpu().numpy()
    out = np.stack([escape_flow(px[i], canon[i, 0], posed[i, 0]) for i in range(len(px))])
    return pixels_to_grid(torch.from_numpy(out).to(target.device, target.dtype))


def flow_targets(out, batch: dict) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """The batch's target flow (grid units) ``(B, 2, H, W)``, visibility ``(B, 1, H, W)`` and
    ``has_flow`` ``(B,)`` in the output's frame (``out.flow_frame``: ``canonical``, the backward ``flow``
    and ``vis``; ``posed``, the forward ``fflow`` and ``fvis``); zeros and False when the batch has none."""
    f_name, v_name = ("fflow", "fvis") if out.flow_frame == "posed" else ("flow", "vis")
    if f_name == "fflow" and "flow" in batch and "fflow" not in batch:
        raise ValueError("the splat head learns a forward flow: its data need data.render.forward_flow=true (and "
                         "data.render.flow_targets=true)")
    if batch.get("has_flow") is None or f_name not in batch:
        has = torch.zeros(out.flow.shape[0], dtype=torch.bool, device=out.flow.device)
        return torch.zeros_like(out.flow), torch.zeros_like(out.mask), has
    return pixels_to_grid(batch[f_name].float()), batch[v_name], batch["has_flow"]


def warp_terms(out, batch: dict, flow_on: str = "visible", offset_smooth: bool = False,
               depth_grad: bool = False, vis_on: str = "foreground", flow_power: float = 1.0) -> dict[str, torch.Tensor]:
    """``flow`` (end-point distance, grid units, to the ``flow_power``, on the pixels ``flow_on`` names), ``vis`` (BCE on the
    pixels ``vis_on`` names), ``smooth`` (flow total variation), with ``offset_smooth`` the depth map's total
    variation and with ``depth_grad`` the depth's slope against the target's
    (:func:`~lit3d.canonical.losses.depth_gradient_loss`); items without flow targets add to the last
    three only."""
    check_choices(flow_on, vis_on)
    target, vis, has = flow_targets(out, batch)
    foreground = batch["mask"] if out.flow_frame == "posed" else batch["canon_mask"]  # of the flow's own frame
    if flow_on == "image" and out.flow_frame == "canonical" and bool(has.any()):
        target = _escape_targets(target, batch)
    where = {"visible": vis, "foreground": foreground, "image": torch.ones_like(foreground)}[flow_on]
    terms = {"flow": flow_loss(out.flow, target, where, has, flow_power),
             "vis": visibility_loss(out.vis_logits, vis, foreground if vis_on == "foreground"
                                    else torch.ones_like(foreground), has),
             "smooth": flow_smoothness(out.flow)}
    if offset_smooth and out.depth_offset is not None:
        terms["offset_smooth"] = flow_smoothness(out.depth_offset)
    if depth_grad:
        terms["depth_grad"] = depth_gradient_loss(out.depth, batch["canon_depth"], batch["canon_mask"])
    return terms
