"""The warp head: the canonical image is the posed image's pixels moved, not redrawn (thesis 5.2.3:
"shifting the pixels to recreate a canonical pose").

From the reconstruction features the head predicts, per canonical pixel,
    flow       (B, 2, H, W)  backward flow in normalised grid units (x, y; 2 = the image width):
                             where in the posed image the pixel's surface point is;
    depth map  (B, 4, H, W)  how the moved depth becomes the canonical depth, on a coarse grid of
                             :data:`AFFINE_CELL` pixels, bilinear: ``c0 + c1 x + c2 y + (1 + c3) D``, the
                             depth of a rigidly moved part under the orthographic camera, (x, y) the
                             sampled posed position in grid units, D its posed depth;
    vis        (B, 1, H, W)  logits: the point is seen in the posed image (take the moved pixel);
    fill       (B, 2, H, W)  depth and mask logits drawn for what the posed view hides.
Output (:func:`warp_compose`): ``mask = v * warp(mask_in) + (1 - v) * fill_mask`` and
``depth = v * map(warp(depth_in)) + (1 - v) * fill_depth``, ``v = sigmoid(vis)``, warps by
bilinear :func:`torch.nn.functional.grid_sample`. The silhouette where visible is the posed one moved.

The output layer starts at zero with the visibility bias at :data:`VIS_BIAS`: an untrained head
returns (almost exactly) the posed input, and zero flow with full visibility returns it exactly.
The flow is learned from flow targets (:mod:`datamodules.canonical.flow`) and, through the warp,
from the image losses.
"""
from __future__ import annotations

import torch
import torch.nn as nn
import torch.nn.functional as F

from lit3d.canonical.outputs import CanonicalOutput

VIS_BIAS = 4.0      # sigmoid(4) = .98: start by taking the moved (at first: unmoved) input pixels
MASK_EPS = 1e-5     # mask probabilities clamped to [eps, 1 - eps] for their logits
N_COEFFS = 4        # the depth map's coefficients c0..c3
AFFINE_CELL = 8     # pixels per cell of the coefficients' coarse grid (a rigid part has constant ones)


def identity_grid(batch: int, height: int, width: int, device=None, dtype=None) -> torch.Tensor:
    """``(B, H, W, 2)`` grid_sample coordinates (x, y in [-1, 1], align_corners=False) of every pixel centre."""
    ys = (torch.arange(height, device=device, dtype=dtype) + 0.5) / height * 2 - 1
    xs = (torch.arange(width, device=device, dtype=dtype) + 0.5) / width * 2 - 1
    gy, gx = torch.meshgrid(ys, xs, indexing="ij")
    return torch.stack([gx, gy], -1)[None].expand(batch, -1, -1, -1)


def sample_grid(flow: torch.Tensor) -> torch.Tensor:
    """``(B, H, W, 2)`` grid_sample coordinates of every pixel + ``flow`` ``(B, 2, H, W)`` (normalised
    units): where each pixel samples."""
    b, _, h, w = flow.shape
    return identity_grid(b, h, w, flow.device, flow.dtype) + flow.permute(0, 2, 3, 1)


def warp_image(image: torch.Tensor, flow: torch.Tensor, grid: torch.Tensor | None = None) -> torch.Tensor:
    """``image`` ``(B, C, H, W)`` sampled at every pixel + ``flow`` ``(B, 2, H, W)`` (normalised units),
    bilinear, zeros outside; ``grid``: :func:`sample_grid` of ``flow`` when the caller has it."""
    grid = sample_grid(flow) if grid is None else grid
    return F.grid_sample(image, grid, mode="bilinear", padding_mode="zeros", align_corners=False)


def pixels_to_grid(flow_px: torch.Tensor) -> torch.Tensor:
    """Flow ``(B, 2, H, W)`` in pixels -> normalised grid units (x by the width, y by the height)."""
    h, w = flow_px.shape[-2:]
    return flow_px * torch.tensor([2.0 / w, 2.0 / h], device=flow_px.device, dtype=flow_px.dtype)[None, :, None, None]


def map_depth(depth: torch.Tensor, coeffs: torch.Tensor, grid: torch.Tensor) -> torch.Tensor:
    """The depth map of the module docstring: ``depth`` ``(B, 1, H, W)`` (a moved pixel's posed depth D)
    and ``coeffs`` ``(B, 4, H, W)`` -> ``c0 + c1 x + c2 y + (1 + c3) D``, ``(x, y)`` from ``grid``
    ``(B, H, W, 2)``: the pixel's posed position in grid units."""
    if coeffs.shape[1] != N_COEFFS:
        raise ValueError(f"depth map: {N_COEFFS} coefficient channels expected, got {coeffs.shape[1]}")
    x, y = grid[..., 0].unsqueeze(1), grid[..., 1].unsqueeze(1)
    return depth + coeffs[:, 0:1] + coeffs[:, 1:2] * x + coeffs[:, 2:3] * y + coeffs[:, 3:4] * depth


def cell_smooth(coeffs: torch.Tensor, cell: int) -> torch.Tensor:
    """``(B, K, H, W)`` averaged over cells of ``cell`` pixels and upsampled bilinearly (unchanged for
    ``cell`` <= 1): the depth map's coefficients, smooth by construction (a rigid part has constant ones)."""
    if cell <= 1:
        return coeffs
    return F.interpolate(F.avg_pool2d(coeffs, cell), size=coeffs.shape[-2:], mode="bilinear", align_corners=False)


def warp_compose(depth: torch.Tensor, mask: torch.Tensor, flow: torch.Tensor, coeffs: torch.Tensor,
                 vis: torch.Tensor, fill_depth: torch.Tensor, fill_mask: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Canonical (depth, mask probability) ``(B, 1, H, W)`` from the posed ``depth``/``mask``, the
    ``flow`` ``(B, 2, H, W)``, the depth map's ``coeffs`` ``(B, 4, H, W)`` (``c0 + c1 x + c2 y + (1 + c3) D``,
    module docstring), visibility probability ``vis`` and the fills (all ``(B, 1, H, W)``, fill mask a
    probability). Zero flow, zero coefficients and ``vis = 1`` give the input."""
    grid = sample_grid(flow)
    moved = warp_image(torch.cat([depth, mask], 1), flow, grid)
    mapped = map_depth(moved[:, 0:1], coeffs, grid)  # (x, y): the sampled posed position
    m = vis * moved[:, 1:2] + (1 - vis) * fill_mask
    d = vis * mapped + (1 - vis) * fill_depth
    return d.clamp(0, 1), m


def zero_layers_(*layers: nn.Module | None) -> None:
    """Weights and biases of the given layers (None skipped) to zero: an output that starts at nothing."""
    for layer in layers:
        if layer is not None:
            nn.init.zeros_(layer.weight)
            nn.init.zeros_(layer.bias)


def coarse_flow_field(linear: nn.Linear | None, latent: torch.Tensor | None, coarse: int, size) -> torch.Tensor | float:
    """The coarse flow ``(B, 2, coarse, coarse)`` that ``linear`` maps the net's latent ``(B, D)`` to,
    upsampled bilinearly to ``size = (H, W)``; 0 without a linear layer or a latent."""
    if linear is None or latent is None:
        return 0.0
    field = linear(latent).view(latent.shape[0], 2, coarse, coarse)
    return F.interpolate(field, size=tuple(size), mode="bilinear", align_corners=False)


def two_convs(cin: int, hidden: int) -> nn.Sequential:
    """Two 3x3 conv + LeakyReLU(0.2) layers, ``(B, cin, H, W) -> (B, hidden, H, W)``."""
    return nn.Sequential(nn.Conv2d(cin, hidden, 3, padding=1), nn.LeakyReLU(0.2),
                         nn.Conv2d(hidden, hidden, 3, padding=1), nn.LeakyReLU(0.2))


class WarpHead(nn.Module):
    """``(B, cin, H, W)`` features and the posed ``depth``, ``mask`` -> :class:`CanonicalOutput` with
    ``flow`` and ``vis_logits`` (module docstring), in two stages.

    1. First flow: with ``latent_dim`` > 0 a linear layer maps the net's global latent
       ``(B, latent_dim)`` to a coarse flow ``(B, 2, coarse, coarse)`` (the pose, seen whole),
       upsampled; to it two 3x3 convs over the features and the pixel coordinates add a per-pixel
       flow (the features are aligned with the posed image, the flow is asked at canonical pixels:
       the coordinates say which).
    2. Refinement: the features are moved by the flow so far into the canonical frame
       (:func:`warp_image`); two 3x3 convs over them, the unmoved features and the coordinates give
       the residual flow, the depth map, the visibility and the fills.

    Every output layer starts at zero (visibility bias :data:`VIS_BIAS`). ``moves_pixels``: the module may
    add the flow terms (:mod:`lit3d.canonical.warp_loss`)."""

    moves_pixels = True

    def __init__(self, cin: int, hidden: int, latent_dim: int = 0, coarse: int = 16):
        super().__init__()
        self.coarse = coarse
        self.coarse_flow = nn.Linear(latent_dim, 2 * coarse * coarse) if latent_dim else None
        self.body = two_convs(cin + 2, hidden)
        self.first = nn.Conv2d(hidden, 2, 1)
        self.refine = two_convs(2 * cin + 2, hidden)
        self.out = nn.Conv2d(hidden, 2 + N_COEFFS + 3, 1)  # flow, depth map, vis, fill depth, fill mask
        self.reset_output_()

    def reset_output_(self) -> None:
        """Output layers to zero, visibility bias :data:`VIS_BIAS`, fill mask bias -4 (an untrained head
        returns the posed input); called again after a whole-net initialisation."""
        zero_layers_(self.first, self.out, self.coarse_flow)
        with torch.no_grad():
            self.out.bias[-3] = VIS_BIAS
            self.out.bias[-1] = -VIS_BIAS

    def parts(self, h: torch.Tensor, latent: torch.Tensor | None = None) -> dict[str, torch.Tensor]:
        """What the head predicts from the features ``h`` ``(B, cin, H, W)`` (and the latent): ``flow``
        ``(B, 2, H, W)``, depth-map ``coeffs`` ``(B, 4, H, W)``, ``vis_logits``, ``fill_depth`` and
        ``fill_mask`` (probabilities) ``(B, 1, H, W)``; :func:`warp_compose` makes the output of them."""
        b, _, height, width = h.shape
        coords = identity_grid(b, height, width, h.device, h.dtype).permute(0, 3, 1, 2)
        body = self.body(torch.cat([h, coords], 1))
        flow = self.first(body) + coarse_flow_field(self.coarse_flow, latent, self.coarse, (height, width))
        o = self.out(self.refine(torch.cat([warp_image(h, flow), h, coords], 1)))
        return {"flow": flow + o[:, 0:2], "coeffs": cell_smooth(o[:, 2:2 + N_COEFFS], AFFINE_CELL),
                "vis_logits": o[:, -3:-2], "fill_depth": torch.sigmoid(o[:, -2:-1]), "fill_mask": torch.sigmoid(o[:, -1:])}

    def forward(self, h: torch.Tensor, depth: torch.Tensor, mask: torch.Tensor,
                latent: torch.Tensor | None = None) -> CanonicalOutput:
        p = self.parts(h, latent)
        d, m = warp_compose(depth, mask, p["flow"], p["coeffs"], torch.sigmoid(p["vis_logits"]), p["fill_depth"],
                            p["fill_mask"])
        m = m.clamp(MASK_EPS, 1 - MASK_EPS)
        return CanonicalOutput(depth=d, mask=m, mask_logits=torch.logit(m), flow=p["flow"], vis_logits=p["vis_logits"])


def require_warp_head(net: nn.Module, **weights: float) -> None:
    """ValueError naming the ``task.warp.<weight>`` that is > 0 where ``net``'s head moves no pixels (not a
    :class:`WarpHead`): those terms exist only with it."""
    on = [k for k, w in weights.items() if w > 0]
    if on and not getattr(getattr(net, "head", None), "moves_pixels", False):
        raise ValueError(f"task.warp.{on[0]}={weights[on[0]]:g} needs the warp head (task.arch=canonical, "
                         "task.net.head.kind=warp); set it to 0 with this net")
