"""The splat head: the posed pixels pushed to where they belong in the canonical image (a forward
flow), instead of pulled from it (the warp head's backward flow, :mod:`lit3d.canonical.warp`).

Why: a backward flow says, per canonical pixel, where to read the posed image. Measured on the demo's
validation figures, the canonical background next to a posed limb reads that limb where it was posed
(the posed mask is flat inside the limb, so the mask loss has no gradient to move the flow off it): the
legs stay in their posed place beside the moved ones. A forward flow moves each posed pixel once;
what it leaves behind is empty.

Per posed pixel the head predicts
    flow       (B, 2, H, W)  forward flow in normalised grid units (x, y; 2 = the image width): where
                             the pixel's surface point lies in the canonical image;
    depth map  (B, K, H, W)  how its posed depth becomes its canonical depth (:func:`map_depth`);
    seen       (B, 1, H, W)  logits: the point is seen in the canonical image (not hidden there);
and per canonical pixel a fill (depth and mask) for what no posed pixel reaches, from the posed
features pushed along with the pixels (:func:`forward_splat`). Output: ``c = min(1, W)``, ``W`` the
splatted weight (posed mask x seen probability, bilinear), ``mask = c + (1 - c) fill_mask``,
``depth = c * splat_depth + (1 - c) fill_mask fill_depth`` (0 where nothing lands and the fill
draws no body; ``splat_depth`` the weighted mean of the mapped depths landing there). Zero flow with
every pixel seen returns the posed input exactly; the output layers start at zero with the seen bias
at :data:`~lit3d.canonical.warp.VIS_BIAS`, so an untrained head returns (almost exactly) the posed input. Its
flow targets need ``data.render.forward_flow=true`` (the forward flow cached beside the backward one); without
them its flow terms refuse the batch.
"""
from __future__ import annotations

import torch
import torch.nn as nn

from lit3d.canonical.outputs import CanonicalOutput
from lit3d.canonical.warp import (MASK_EPS, VIS_BIAS, PixelMover, cell_smooth, coarse_flow_field, identity_grid,
                                  map_depth, two_convs, zero_layers_)


def forward_splat(values: torch.Tensor, weight: torch.Tensor, flow: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Push every pixel of ``values`` ``(B, C, H, W)``, weighted by ``weight`` ``(B, 1, H, W)``, by ``flow``
    ``(B, 2, H, W)`` (normalised grid units, align_corners=False) and share it bilinearly among the 4
    pixels around where it lands (outside the image: dropped). Returns the sums ``(B, C, H, W)`` of
    weight x value and the summed weight ``(B, 1, H, W)`` per pixel; differentiable in all three
    (in ``flow`` through the bilinear shares)."""
    b, c, h, w = values.shape
    scale = torch.tensor([w / 2.0, h / 2.0], device=flow.device, dtype=flow.dtype)[None, :, None, None]
    ys, xs = torch.meshgrid(torch.arange(h, device=flow.device, dtype=flow.dtype),
                            torch.arange(w, device=flow.device, dtype=flow.dtype), indexing="ij")
    target = flow * scale  # pixels
    tx, ty = xs + target[:, 0], ys + target[:, 1]
    x0, y0 = tx.floor(), ty.floor()
    carried = torch.cat([values * weight, weight], 1).reshape(b, c + 1, h * w)
    out = carried.new_zeros(b, c + 1, h * w)
    for xi in (x0, x0 + 1):
        for yi in (y0, y0 + 1):
            share = (1 - (tx - xi).abs()) * (1 - (ty - yi).abs())
            inside = (xi >= 0) & (xi <= w - 1) & (yi >= 0) & (yi <= h - 1)
            index = (yi.clamp(0, h - 1) * w + xi.clamp(0, w - 1)).long().reshape(b, 1, h * w)
            out.scatter_add_(2, index.expand(-1, c + 1, -1), carried * (share * inside).reshape(b, 1, h * w))
    out = out.reshape(b, c + 1, h, w)
    return out[:, :c], out[:, c:]


class SplatHead(PixelMover):
    """``(B, cin, H, W)`` features (aligned with the posed image) and the posed ``depth``, ``mask`` ->
    :class:`CanonicalOutput` whose ``flow`` and ``vis_logits`` are the forward flow and the seen logits
    at the *posed* pixels (``flow_frame="posed"``; module docstring).

    Stage 1, at posed pixels: two 3x3 convs over the features and the pixel coordinates; a 1x1 layer
    gives the forward flow (plus, with ``latent_dim`` > 0, a coarse flow from the net's global latent,
    upsampled), the depth map's coefficients (cell-averaged, ``affine_cell``) and the seen logit.
    Stage 2, at canonical pixels: the features pushed with the pixels (weighted mean), the coverage and
    the coordinates through two 3x3 convs and a 1x1 layer give the fill's depth and mask."""

    def __init__(self, cin: int, hidden: int, latent_dim: int = 0, coarse: int = 16, depth_model: str = "offset",
                 affine_cell: int = 8):
        super().__init__(latent_dim, coarse, depth_model, affine_cell)
        self.body = two_convs(cin + 2, hidden)
        self.posed_out = nn.Conv2d(hidden, 2 + self.n_coeffs + 1, 1)  # flow, depth map, seen
        self.fill_body = two_convs(cin + 1 + 2, hidden)
        self.fill_out = nn.Conv2d(hidden, 2, 1)  # fill depth, fill mask
        self.reset_output_()

    def reset_output_(self) -> None:
        """Output layers to zero, seen bias :data:`VIS_BIAS`, fill mask bias -VIS_BIAS (an untrained head
        returns the posed input); called again after a whole-net initialisation."""
        zero_layers_(self.posed_out, self.fill_out, self.coarse_flow)
        with torch.no_grad():
            self.posed_out.bias[-1] = VIS_BIAS
            self.fill_out.bias[-1] = -VIS_BIAS

    def forward(self, h: torch.Tensor, depth: torch.Tensor, mask: torch.Tensor,
                latent: torch.Tensor | None = None) -> CanonicalOutput:
        b, _, height, width = h.shape
        grid = identity_grid(b, height, width, h.device, h.dtype)
        coords = grid.permute(0, 3, 1, 2)
        o = self.posed_out(self.body(torch.cat([h, coords], 1)))
        flow = o[:, 0:2] + coarse_flow_field(self.coarse_flow, latent, self.coarse, (height, width))
        coeffs = cell_smooth(o[:, 2:2 + self.n_coeffs], self.affine_cell)
        seen_logits = o[:, -1:]
        mapped = map_depth(depth, coeffs, grid)
        sums, weight = forward_splat(torch.cat([mapped, h], 1), mask * torch.sigmoid(seen_logits), flow)
        mean = sums / weight.clamp_min(1e-3)
        cover = weight.clamp(max=1.0)
        f = self.fill_out(self.fill_body(torch.cat([mean[:, 1:], cover, coords], 1)))
        fill_depth, fill_mask = torch.sigmoid(f[:, 0:1]), torch.sigmoid(f[:, 1:2])
        m = (cover + (1 - cover) * fill_mask).clamp(MASK_EPS, 1 - MASK_EPS)
        d = (cover * mean[:, 0:1] + (1 - cover) * fill_mask * fill_depth).clamp(0, 1)  # 0: the background
        return CanonicalOutput(depth=d, mask=m, mask_logits=torch.logit(m), flow=flow, vis_logits=seen_logits,
                               depth_offset=coeffs, flow_frame="posed")
