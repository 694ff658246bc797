"""The warp head: the canonical image is the posed image's pixels moved, not redrawn (thesis 5.2.3:
"shifting the pixels to recreate a canonical pose").

From the reconstruction features the head predicts, per canonical pixel,
    flow       (B, 2, H, W)  backward flow in normalised grid units (x, y; 2 = the image width):
                             where in the posed image the pixel's surface point is;
    depth map  (B, K, H, W)  how the moved depth becomes the canonical depth (:data:`DEPTH_MODELS`):
                             ``offset`` (K = 1): ``D + c0``; ``affine`` (K = 4, on a coarse grid of
                             ``affine_cell`` pixels, bilinear): ``c0 + c1 x + c2 y + (1 + c3) D``, the
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

import math

import torch
import torch.nn as nn
import torch.nn.functional as F

from lit3d.canonical.outputs import CanonicalOutput

VIS_BIAS = 4.0      # sigmoid(4) = .98: start by taking the moved (at first: unmoved) input pixels
MASK_EPS = 1e-5     # mask probabilities clamped to [eps, 1 - eps] for their logits
DEPTH_MODELS = {"offset": 1, "affine": 4}  # depth-map coefficient channels per model


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
    and ``coeffs`` ``(B, K, H, W)`` -> ``D + c0`` (K = 1) or ``c0 + c1 x + c2 y + (1 + c3) D`` (K = 4),
    ``(x, y)`` from ``grid`` ``(B, H, W, 2)``: the pixel's posed position in grid units."""
    mapped = depth + coeffs[:, 0:1]
    if coeffs.shape[1] == 4:
        x, y = grid[..., 0].unsqueeze(1), grid[..., 1].unsqueeze(1)
        mapped = mapped + coeffs[:, 1:2] * x + coeffs[:, 2:3] * y + coeffs[:, 3:4] * depth
    return mapped


def cell_smooth(coeffs: torch.Tensor, cell: int) -> torch.Tensor:
    """``(B, K, H, W)`` averaged over cells of ``cell`` pixels and upsampled bilinearly (unchanged for
    ``cell`` <= 1): the depth map's coefficients, smooth by construction (a rigid part has constant ones)."""
    if cell <= 1:
        return coeffs
    return F.interpolate(F.avg_pool2d(coeffs, cell), size=coeffs.shape[-2:], mode="bilinear", align_corners=False)


def warp_compose(depth: torch.Tensor, mask: torch.Tensor, flow: torch.Tensor, coeffs: torch.Tensor,
                 vis: torch.Tensor, fill_depth: torch.Tensor, fill_mask: torch.Tensor,
                 normalise: bool = False) -> tuple[torch.Tensor, torch.Tensor]:
    """Canonical (depth, mask probability) ``(B, 1, H, W)`` from the posed ``depth``/``mask``, the
    ``flow`` ``(B, 2, H, W)``, the depth map's ``coeffs`` ``(B, K, H, W)`` (K = 1: an offset ``c0``;
    K = 4: ``c0 + c1 x + c2 y + (1 + c3) D``, module docstring), visibility probability ``vis`` and
    the fills (all ``(B, 1, H, W)``, fill mask a probability). Zero flow, zero coefficients and
    ``vis = 1`` give the input. ``normalise``: the moved depth is divided by the moved mask (where it
    exceeds 1e-3), so a sample across the silhouette's edge keeps the body's depth instead of mixing
    in the background's 0."""
    grid = sample_grid(flow)
    moved = warp_image(torch.cat([depth, mask], 1), flow, grid)
    moved_depth = moved[:, 0:1]
    if normalise:
        moved_depth = torch.where(moved[:, 1:2] > 1e-3, moved_depth / moved[:, 1:2].clamp_min(1e-3),
                                  torch.zeros_like(moved_depth))
    mapped = map_depth(moved_depth, coeffs, grid)  # (x, y): the sampled posed position
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


class PixelMover(nn.Module):
    """What the warp and splat heads share: the depth model's coefficient count (``n_coeffs``) and cell
    (``affine_cell``), and the linear layer from the net's latent ``(B, latent_dim)`` to a coarse flow
    ``(B, 2, coarse, coarse)`` (None for ``latent_dim`` 0). ``moves_pixels``: the module may add the
    depth-map and flow terms (:func:`require_warp_head`)."""

    moves_pixels = True

    def __init__(self, latent_dim: int, coarse: int, depth_model: str, affine_cell: int):
        super().__init__()
        if depth_model not in DEPTH_MODELS:
            raise ValueError(f"unknown warp depth model '{depth_model}' ({', '.join(DEPTH_MODELS)})")
        self.n_coeffs = DEPTH_MODELS[depth_model]
        self.affine_cell = affine_cell if depth_model == "affine" else 1
        self.coarse = coarse
        self.coarse_flow = nn.Linear(latent_dim, 2 * coarse * coarse) if latent_dim else None


class AttendFlow(nn.Module):
    """A coarse flow found by search: every canonical cell of a ``grid`` x ``grid`` raster attends over the
    posed cells and reads where its surface point is. Keys: a 1x1 conv of the posed features and
    coordinates, average-pooled to the raster ``(B, C, G, G)``; queries: a learned map per canonical cell
    ``(C, G, G)`` (what belongs there in the canonical pose), plus, with a latent, a linear term of it
    (the figure's build). Logits ``gain q . k / sqrt(C) - |x_q - x_k|^2 / (2 sigma^2)`` (a locality prior
    with a learned width, ``sigma`` in grid units, starting at ``sigma_cells`` cells); the flow is the
    attention's mean key position minus that of the prior alone, upsampled bilinearly.

    Why: a backward flow must find where a limb went, which may be 40 px away at 128^2; local convs
    see a few pixels, and the demo's flow left the quadrupeds' legs where they were posed. Attention
    compares every posed cell. The query map starts at zero, so the attention is the prior's and the
    flow exactly zero."""

    def __init__(self, cin: int, channels: int, grid: int, latent_dim: int = 0, sigma_cells: float = 4.0,
                 gain: float = 20.0):
        super().__init__()
        self.grid = grid
        # Adam moves a weight by about lr a step: without a gain the queries, started at zero, give logits
        # below 1 after the demo's 240 steps (measured: the attention's flow .3 px of the true 4.6 px)
        self.gain = gain
        self.key = nn.Conv2d(cin + 2, channels, 1)
        self.query = nn.Parameter(torch.zeros(1, channels, grid, grid))
        self.query_latent = nn.Linear(latent_dim, channels) if latent_dim else None
        self.log_sigma = nn.Parameter(torch.tensor(math.log(sigma_cells * 2.0 / grid)))

    def reset_output_(self) -> None:
        """Queries to zero: the attention is the locality prior's, the flow zero."""
        nn.init.zeros_(self.query)
        zero_layers_(self.query_latent)

    def forward(self, h: torch.Tensor, latent: torch.Tensor | None = None) -> torch.Tensor:
        """``(B, 2, H, W)`` flow (grid units) from the posed features ``h`` ``(B, cin, H, W)`` and the latent."""
        b, _, height, width = h.shape
        g = self.grid
        cells = identity_grid(b, g, g, h.device, h.dtype)  # (B, G, G, 2): cell centres, posed and canonical alike
        pooled = F.adaptive_avg_pool2d(h, g)
        keys = self.key(torch.cat([pooled, cells.permute(0, 3, 1, 2)], 1)).flatten(2)  # (B, C, N)
        query = self.query.expand(b, -1, -1, -1)
        if self.query_latent is not None and latent is not None:
            query = query + self.query_latent(latent)[:, :, None, None]
        query = query.flatten(2)  # (B, C, N)
        pos = cells[:1].reshape(1, g * g, 2)  # the same for every item: the prior once, broadcast over the batch
        prior = -torch.cdist(pos, pos).pow(2) / (2 * self.log_sigma.exp() ** 2)  # (1, N query, N key)
        logits = self.gain * torch.einsum("bcq,bck->bqk", query, keys) / math.sqrt(keys.shape[1]) + prior
        shift = torch.softmax(logits, -1) @ pos - torch.softmax(prior, -1) @ pos  # (B, N, 2)
        field = shift.transpose(1, 2).reshape(b, 2, g, g)
        return F.interpolate(field, size=(height, width), mode="bilinear", align_corners=False)


class PartFlow(nn.Module):
    """A flow made of ``parts`` rigid (affine) motions blended per pixel, as skinning blends bones:
    ``flow(x) = sum_k w_k(x) ((A_k - I) x + t_k)``, ``x`` the pixel's grid position, ``w`` a softmax over
    part logits from the features ``(B, hidden, H, W)`` (a 1x1 conv: which part a canonical pixel
    belongs to), ``(A_k, t_k)`` per item from the net's latent ``(B, latent_dim)`` (a linear layer: the
    pose, seen whole). A limb is a few numbers to learn instead of a field, and the background next to a
    canonical limb moves with it, off the posed limb. The motions start at the identity (zero flow); the
    part logits keep their random start (equal parts would stay equal)."""

    def __init__(self, hidden: int, latent_dim: int, parts: int):
        super().__init__()
        self.parts = parts
        self.logits = nn.Conv2d(hidden, parts, 1)
        self.motion = nn.Linear(latent_dim, parts * 6)

    def reset_output_(self) -> None:
        """The motions to the identity (zero flow)."""
        zero_layers_(self.motion)

    def forward(self, feats: torch.Tensor, latent: torch.Tensor, grid: torch.Tensor) -> torch.Tensor:
        """``(B, 2, H, W)`` flow from the features, the latent and the pixels' grid positions ``(B, H, W, 2)``."""
        b = feats.shape[0]
        w = torch.softmax(self.logits(feats), 1)  # (B, K, H, W)
        m = self.motion(latent).view(b, self.parts, 2, 3)  # (A - I | t) per part
        xy1 = torch.cat([grid, torch.ones_like(grid[..., :1])], -1)  # (B, H, W, 3)
        disp = torch.einsum("bkij,bhwj->bkihw", m, xy1)  # (B, K, 2, H, W)
        return (w.unsqueeze(2) * disp).sum(1)


class WarpHead(PixelMover):
    """``(B, cin, H, W)`` features and the posed ``depth``, ``mask`` -> :class:`CanonicalOutput` with
    ``flow`` and ``vis_logits`` (module docstring), in two stages.

    1. First flow: with ``latent_dim`` > 0 a linear layer maps the net's global latent
       ``(B, latent_dim)`` to a coarse flow ``(B, 2, coarse, coarse)`` (the pose, seen whole),
       upsampled; to it two 3x3 convs over the features and the pixel coordinates add a per-pixel
       flow (the features are aligned with the posed image, the flow is asked at canonical pixels:
       the coordinates say which); ``parts`` > 0 adds :class:`PartFlow`, ``attend_grid`` > 0
       :class:`AttendFlow` (a search over the posed cells).
    2. Refinement: the features are moved by the flow so far into the canonical frame
       (:func:`warp_image`); two 3x3 convs over them, the unmoved features and the coordinates give
       a residual flow. ``refine_steps`` - 1 such steps correct only the flow (each its own layers, as
       iterative optical-flow refinement: a far-moving limb is found a step at a time); the last one
       gives the residual flow, the depth offset, the visibility and the fills.

    Every output layer starts at zero (visibility bias :data:`VIS_BIAS`)."""

    def __init__(self, cin: int, hidden: int, latent_dim: int = 0, coarse: int = 16, normalise_depth: bool = False,
                 depth_model: str = "offset", affine_cell: int = 8, parts: int = 0, refine_steps: int = 1,
                 attend_grid: int = 0):
        super().__init__(latent_dim, coarse, depth_model, affine_cell)
        if parts and not latent_dim:
            raise ValueError("task.net.head.parts > 0 needs the MSFE's latent (task.net.msfe.use=true)")
        if refine_steps < 1:
            raise ValueError(f"warp_refine_steps must be >= 1 (got {refine_steps})")
        self.part_flow = PartFlow(hidden, latent_dim, parts) if parts else None
        self.attend = AttendFlow(cin, hidden, attend_grid, latent_dim) if attend_grid else None
        self.normalise_depth = normalise_depth  # warp_compose(normalise=...): no edge mixing
        self.body = two_convs(cin + 2, hidden)
        self.first = nn.Conv2d(hidden, 2, 1)
        self.steps = nn.ModuleList(nn.Sequential(two_convs(2 * cin + 2, hidden), nn.Conv2d(hidden, 2, 1))
                                   for _ in range(refine_steps - 1))  # flow-only refinement steps
        self.refine = two_convs(2 * cin + 2, hidden)
        self.out = nn.Conv2d(hidden, 2 + self.n_coeffs + 3, 1)  # flow, depth map, vis, fill depth, fill mask
        self.reset_output_()

    def reset_output_(self) -> None:
        """Output layers to zero, visibility bias :data:`VIS_BIAS`, fill mask bias -4 (an untrained head
        returns the posed input); called again after a whole-net initialisation."""
        zero_layers_(self.first, self.out, self.coarse_flow, *(step[-1] for step in self.steps))
        for flow_part in (self.part_flow, self.attend):
            if flow_part is not None:
                flow_part.reset_output_()
        with torch.no_grad():
            self.out.bias[-3] = VIS_BIAS
            self.out.bias[-1] = -VIS_BIAS

    def parts(self, h: torch.Tensor, latent: torch.Tensor | None = None) -> dict[str, torch.Tensor]:
        """What the head predicts from the features ``h`` ``(B, cin, H, W)`` (and the latent): ``flow``
        ``(B, 2, H, W)``, depth-map ``coeffs`` ``(B, K, H, W)``, ``vis_logits``, ``fill_depth`` and
        ``fill_mask`` (probabilities) ``(B, 1, H, W)``; :func:`warp_compose` makes the output of them."""
        b, _, height, width = h.shape
        coords = identity_grid(b, height, width, h.device, h.dtype).permute(0, 3, 1, 2)
        body = self.body(torch.cat([h, coords], 1))
        flow = self.first(body) + coarse_flow_field(self.coarse_flow, latent, self.coarse, (height, width))
        if self.part_flow is not None and latent is not None:
            flow = flow + self.part_flow(body, latent, coords.permute(0, 2, 3, 1))
        if self.attend is not None:
            flow = flow + self.attend(h, latent)
        for step in self.steps:
            flow = flow + step(torch.cat([warp_image(h, flow), h, coords], 1))
        o = self.out(self.refine(torch.cat([warp_image(h, flow), h, coords], 1)))
        return {"flow": flow + o[:, 0:2], "coeffs": cell_smooth(o[:, 2:2 + self.n_coeffs], self.affine_cell),
                "vis_logits": o[:, -3:-2], "fill_depth": torch.sigmoid(o[:, -2:-1]), "fill_mask": torch.sigmoid(o[:, -1:])}

    def forward(self, h: torch.Tensor, depth: torch.Tensor, mask: torch.Tensor,
                latent: torch.Tensor | None = None) -> CanonicalOutput:
        p = self.parts(h, latent)
        d, m = warp_compose(depth, mask, p["flow"], p["coeffs"], torch.sigmoid(p["vis_logits"]), p["fill_depth"],
                            p["fill_mask"], self.normalise_depth)
        m = m.clamp(MASK_EPS, 1 - MASK_EPS)
        return CanonicalOutput(depth=d, mask=m, mask_logits=torch.logit(m), flow=p["flow"], vis_logits=p["vis_logits"],
                               depth_offset=p["coeffs"])


def require_warp_head(net: nn.Module, **weights: float) -> None:
    """ValueError naming the ``task.warp.<weight>`` that is > 0 where ``net``'s head moves no pixels (neither a
    :class:`WarpHead` nor :class:`lit3d.canonical.splat.SplatHead`): those terms (offset smoothness,
    depth slope) exist only with them."""
    on = [k for k, w in weights.items() if w > 0]
    if on and not getattr(getattr(net, "head", None), "moves_pixels", False):
        raise ValueError(f"task.warp.{on[0]}={weights[on[0]]:g} needs the warp head (task.arch=canonical, "
                         "task.net.head.kind=warp or splat); set it to 0 with this net")
