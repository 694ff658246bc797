"""The warp head's loss terms (:mod:`lit3d.canonical.warp`), from a net output and a batch.

Batch keys (``datamodules.canonical`` with ``data.render.flow_targets=true``): ``flow`` ``(B, 2, H, W)`` in
pixels and ``vis`` ``(B, 1, H, W)`` (backward, at canonical pixels), ``has_flow`` ``(B,)`` bool, ``canon_mask``
``(B, 1, H, W)``. The flow's end-point distance is paid on the canonical pixels whose surface point the posed
image shows, the visibility on the canonical foreground. Batches without flow targets (FAUST) give zero flow
and visibility terms.
"""
from __future__ import annotations

import torch

from lit3d.canonical.losses import flow_loss, flow_smoothness, visibility_loss
from lit3d.canonical.warp import pixels_to_grid


def flow_targets(out, batch: dict) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """The batch's target flow (grid units) ``(B, 2, H, W)``, visibility ``(B, 1, H, W)`` and ``has_flow``
    ``(B,)``; zeros and False when the batch has none."""
    if batch.get("has_flow") is None or "flow" not in batch:
        has = torch.zeros(out.flow.shape[0], dtype=torch.bool, device=out.flow.device)
        return torch.zeros_like(out.flow), torch.zeros_like(out.mask), has
    return pixels_to_grid(batch["flow"].float()), batch["vis"], batch["has_flow"]


def warp_terms(out, batch: dict) -> dict[str, torch.Tensor]:
    """``flow`` (end-point distance, grid units, on the visible pixels), ``vis`` (BCE on the canonical
    foreground) and ``smooth`` (the flow's total variation); items without flow targets add to the last only."""
    target, vis, has = flow_targets(out, batch)
    return {"flow": flow_loss(out.flow, target, vis, has),
            "vis": visibility_loss(out.vis_logits, vis, batch["canon_mask"], has),
            "smooth": flow_smoothness(out.flow)}
