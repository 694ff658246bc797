"""Canonical-form network of thesis chapter 5: LFE + MSFE + reconstruction, and a plain U-Net baseline.

Every block is size-agnostic: it keeps the thesis's layer structure (3 down / 5 up
blocks, 3 dilated encoders + fuser + 7 transposed convolutions) and resizes its
output to the input's spatial size at the end, so 500^2 (paper) and 64^2/128^2
(tests, demo) run through the same code.

Tensors (B = batch, H x W = image size):
    depth (B, 1, H, W) float32 in [0, 1] (0 = background)
    mask  (B, 1, H, W) float32 in {0, 1}
    CanonicalNet(depth, mask) -> CanonicalOutput(depth (B,1,H,W) in [0,1], mask (B,1,H,W) in [0,1],
                                                 mask_logits (B,1,H,W))

Sizes live in the configs only (``conf/task/canonical.yaml``: demo scale;
``conf/experiment/canonical_paper.yaml``: the thesis's; ``canonical_tiny.yaml``: CPU tests).
Paper sizes at 500^2: per-encoder latent 10 x 40 x 40 = 16,000 (adaptive average pooling to a
40 x 40 grid makes it size-agnostic), fused 48,000 -> two MLP layers -> 500, decoded by
transposed convolutions with kernels 3, 3, 6, 2, 2, 2, 3 (stride 2) and resized to the input size.
"""
from __future__ import annotations

from collections.abc import Sequence

import torch
import torch.nn as nn
import torch.nn.functional as F

from lit3d.canonical.outputs import CanonicalOutput, OutputHead
from lit3d.canonical.warp import WarpHead
from lit3d.canonical.net_settings import HeadSettings, LFESettings, MSFESettings, ReconstructionSettings
from lit3d.canonical.settings import parse

UP_KERNELS = (5, 3, 5, 2, 2)
UP_STRIDES = (1, 1, 2, 2, 2)  # three stride-2 ups undo the three 2x max-pools
MSFE_KERNELS = (3, 3, 6, 2, 2, 2, 3)
DILATIONS = (1, 2, 3)

def resize_to(x: torch.Tensor, size: Sequence[int]) -> torch.Tensor:
    """Bilinear resize (or identity) of ``(B, C, h, w)`` to ``size = (H, W)``."""
    if tuple(x.shape[-2:]) == tuple(size):
        return x
    return F.interpolate(x, size=tuple(size), mode="bilinear", align_corners=False)


def _up(cin: int, cout: int, k: int, s: int) -> nn.ConvTranspose2d:
    """Transposed conv that keeps the size (s=1, odd k) or doubles it (s=2)."""
    if s == 1:
        return nn.ConvTranspose2d(cin, cout, k, stride=1, padding=(k - 1) // 2)
    pad = max(-(-(k - s) // 2), 0)  # ceil((k - s) / 2): output = s * n
    out_pad = 2 * pad - (k - s)
    return nn.ConvTranspose2d(cin, cout, k, stride=s, padding=pad, output_padding=out_pad)


class DownUp(nn.Module):
    """3 down blocks [Conv2d k=5 s=1, LeakyReLU, MaxPool 2] then 5 up blocks [ConvTranspose2d, activation].

    ``(B, cin, H, W) -> (B, cout, H, W)``: up kernels 5, 3, 5, 2, 2 (strides 1, 1, 2, 2, 2),
    the result is resized to the input size. The last up block has no activation
    (``final_act=False``) so it can feed a head or carry signed features.
    """

    def __init__(self, cin: int, cout: int, channels: Sequence[int], kernel: int = 5,
                 up_act: str = "leaky", final_act: bool = True):
        super().__init__()
        c = list(channels)
        downs, prev = [], cin
        for ch in c:
            downs += [nn.Conv2d(prev, ch, kernel, stride=1, padding=kernel // 2), nn.LeakyReLU(0.2), nn.MaxPool2d(2)]
            prev = ch
        self.down = nn.Sequential(*downs)
        up_ch = [c[-1], c[-1], c[-2], c[-3], max(c[-3] // 2, cout)]
        ups = []
        for i, (k, s) in enumerate(zip(UP_KERNELS, UP_STRIDES)):
            last = i == len(UP_KERNELS) - 1
            out = cout if last else up_ch[i + 1]
            ups.append(_up(prev, out, k, s))
            if not last or final_act:
                ups.append(nn.LeakyReLU(0.2) if up_act == "leaky" else nn.ReLU())
            prev = out
        self.up = nn.Sequential(*ups)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return resize_to(self.up(self.down(x)), x.shape[-2:])


class LFE(DownUp):
    """Local feature extractor: ``(B, 2, H, W)`` depth+mask -> ``(B, out, H, W)`` local features."""

    def __init__(self, cin: int, out: int, channels: Sequence[int]):
        super().__init__(cin, out, channels, up_act="leaky", final_act=True)


class DilatedEncoder(nn.Module):
    """3 x [Conv2d k=3 dilation d, LeakyReLU, AvgPool 2] -> adaptive avg-pool to grid -> flat latent.

    ``(B, cin, H, W) -> (B, channels[-1] * grid * grid)`` for any H, W >= 8.
    """

    def __init__(self, cin: int, channels: Sequence[int], dilation: int, grid: int):
        super().__init__()
        layers, prev = [], cin
        for ch in channels:
            layers += [nn.Conv2d(prev, ch, 3, padding=dilation, dilation=dilation), nn.LeakyReLU(0.2), nn.AvgPool2d(2)]
            prev = ch
        self.body = nn.Sequential(*layers)
        self.pool = nn.AdaptiveAvgPool2d(grid)
        self.latent_dim = prev * grid * grid

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.pool(self.body(x)).flatten(1)


class MSFE(nn.Module):
    """Multi-scale feature extractor: 3 dilated encoders (1, 2, 3), fuser MLP, transposed-conv decoder.

    ``(B, cin, H, W) -> (B, out, H, W)``. Latents z1, z2, z3 are concatenated
    (3 x latent), mapped by two linear layers to ``fuser_out`` (500 at paper scale),
    reshaped to ``(fuser_out, 1, 1)`` and decoded by 7 transposed convolutions (kernels
    3, 3, 6, 2, 2, 2, 3, ReLU; stride 2 until the map reaches ``image_size``, then stride 1),
    then resized to H x W (at 500^2: seven stride-2 layers give 289^2, resized to 500^2).
    """

    def __init__(self, cin: int, out: int, channels: Sequence[int], grid: int, fuser_hidden: int, fuser_out: int,
                 dec_channels: Sequence[int], image_size: int, dilations: Sequence[int] = DILATIONS):
        super().__init__()
        self.encoders = nn.ModuleList(DilatedEncoder(cin, channels, d, grid) for d in dilations)
        self.latent_dim = sum(e.latent_dim for e in self.encoders)
        self.fuser = nn.Sequential(nn.Linear(self.latent_dim, fuser_hidden), nn.LeakyReLU(0.2),
                                   nn.Linear(fuser_hidden, fuser_out), nn.LeakyReLU(0.2))
        dec, prev = [], fuser_out
        chans = list(dec_channels) + [out]
        if len(chans) != len(MSFE_KERNELS):
            raise ValueError(f"msfe_dec_channels needs {len(MSFE_KERNELS) - 1} entries, got {len(dec_channels)}")
        size = 1
        for i, (k, ch) in enumerate(zip(MSFE_KERNELS, chans)):
            # stride 2 while the map is smaller than the image, then stride 1 (no wasted work
            # at small image sizes); at 500^2 all seven are stride 2 (1 -> 289)
            stride = 2 if size < image_size else 1
            pad = (k - 1) // 2 if stride == 1 else 0
            dec.append(nn.ConvTranspose2d(prev, ch, k, stride=stride, padding=pad))
            size = (size - 1) * stride - 2 * pad + k
            if i < len(MSFE_KERNELS) - 1:
                dec.append(nn.ReLU())
            prev = ch
        self.decoder = nn.Sequential(*dec)

    def encode(self, x: torch.Tensor) -> torch.Tensor:
        """``(B, cin, H, W)`` -> fused latent ``(B, fuser_out)``."""
        return self.fuser(torch.cat([e(x) for e in self.encoders], dim=1))

    def decode(self, f: torch.Tensor, size: Sequence[int]) -> torch.Tensor:
        """Fused latent ``(B, fuser_out)`` -> ``(B, out, *size)``."""
        return resize_to(self.decoder(f[:, :, None, None]), size)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.decode(self.encode(x), x.shape[-2:])


class CanonicalNet(nn.Module):
    """LFE -> MSFE -> reconstruction (thesis Fig. 5.1), with ablation switches.

    The parts are the nodes of :mod:`lit3d.canonical.net_settings` (mappings or their dataclasses):
    ``lfe.use=False`` drops the LFE (the MSFE and the reconstruction see depth+mask only);
    ``msfe.use=False`` drops the MSFE. Reconstruction input = [depth, mask, Y_LFE, Y_MSFE].
    ``head.kind``: ``redraw`` (the thesis: a 1x1 conv draws depth and mask) or ``warp``
    (:class:`~lit3d.canonical.warp.WarpHead`: moves the posed pixels, ``head.hidden`` channels; its
    coarse flow comes from the MSFE's fused latent).
    """

    def __init__(self, image_size: int, lfe: dict | LFESettings, msfe: dict | MSFESettings,
                 reconstruction: dict | ReconstructionSettings, head: dict | HeadSettings | None = None):
        super().__init__()
        lfe, msfe = parse(LFESettings, lfe, "net.lfe"), parse(MSFESettings, msfe, "net.msfe")
        rec = parse(ReconstructionSettings, reconstruction, "net.reconstruction")
        head = parse(HeadSettings, head, "net.head")
        self.image_size = image_size
        self.lfe = LFE(2, lfe.out, lfe.channels) if lfe.use else None
        c = 2 + (lfe.out if lfe.use else 0)
        self.msfe = MSFE(c, msfe.out, msfe.channels, msfe.grid, msfe.fuser_hidden, msfe.fuser_out, msfe.dec_channels,
                         image_size) if msfe.use else None
        c += msfe.out if msfe.use else 0
        if rec.kind == "unet":  # skip connections: full-resolution features for the flow
            self.reconstruction = UNetTrunk(c, rec.channels)
            hidden = self.reconstruction.out_channels
        else:
            hidden = max(rec.channels[0] // 2, 4)
            self.reconstruction = DownUp(c, hidden, rec.channels, up_act="leaky", final_act=True)
        # the input is given to the head again (skip link)
        latent = msfe.fuser_out if msfe.use else 0
        if head.kind == "warp":
            self.head = WarpHead(hidden + 2, head.hidden, latent)
        else:
            self.head = OutputHead(hidden + 2)

    def features(self, depth: torch.Tensor, mask: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor | None]:
        """The head's input ``(B, hidden + 2, H, W)`` (the reconstruction's features and the posed depth and
        mask) and the MSFE's fused latent ``(B, fuser_out)`` (None without the MSFE)."""
        x = torch.cat([depth, mask], dim=1)
        feats, latent = [x], None
        if self.lfe is not None:
            feats.append(self.lfe(x))
        if self.msfe is not None:
            latent = self.msfe.encode(torch.cat(feats, dim=1))
            feats.append(self.msfe.decode(latent, x.shape[-2:]))
        return torch.cat([self.reconstruction(torch.cat(feats, dim=1)), x], dim=1), latent

    def forward(self, depth: torch.Tensor, mask: torch.Tensor) -> CanonicalOutput:
        h, latent = self.features(depth, mask)
        out = self.head(h, depth, mask, latent) if getattr(self.head, "moves_pixels", False) else self.head(h)
        out.latent = latent
        return out


class UNetTrunk(nn.Module):
    """Encoder-decoder with skip connections: ``(B, cin, H, W) -> (B, channels[0], H, W)``; per level two
    3x3 convs (LeakyReLU 0.2) and a 2x max-pool, a 3x3 conv at the bottom, transposed-conv ups joined
    with the skips. Pads the input to a multiple of ``2**len(channels)`` and crops back (size-agnostic)."""

    def __init__(self, cin: int, channels: Sequence[int]):
        super().__init__()
        ch = list(channels)
        self.enc = nn.ModuleList()
        prev = cin
        for c in ch:
            self.enc.append(nn.Sequential(nn.Conv2d(prev, c, 3, padding=1), nn.LeakyReLU(0.2),
                                          nn.Conv2d(c, c, 3, padding=1), nn.LeakyReLU(0.2)))
            prev = c
        self.bottom = nn.Sequential(nn.Conv2d(prev, prev, 3, padding=1), nn.LeakyReLU(0.2))
        self.ups = nn.ModuleList()
        self.dec = nn.ModuleList()
        for c in reversed(ch):
            self.ups.append(nn.ConvTranspose2d(prev, c, 2, stride=2))
            self.dec.append(nn.Sequential(nn.Conv2d(2 * c, c, 3, padding=1), nn.LeakyReLU(0.2)))
            prev = c
        self.out_channels = prev
        self.factor = 2 ** len(ch)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        H, W = x.shape[-2:]
        ph, pw = (-H) % self.factor, (-W) % self.factor
        x = F.pad(x, (0, pw, 0, ph))
        skips = []
        for enc in self.enc:
            x = enc(x)
            skips.append(x)
            x = F.max_pool2d(x, 2)
        x = self.bottom(x)
        for up, dec, s in zip(self.ups, self.dec, reversed(skips)):
            x = dec(torch.cat([up(x), s], dim=1))
        return x[..., :H, :W]


class UNet(UNetTrunk):
    """Plain U-Net baseline: ``(depth, mask)`` -> ``CanonicalOutput``: the :class:`UNetTrunk` (its
    parameters at the top level, as checkpoints hold them) and the redraw head (a 1x1 conv)."""

    def __init__(self, channels: Sequence[int], image_size: int):
        super().__init__(2, channels)
        self.image_size = image_size
        self.head = OutputHead(self.out_channels)

    def forward(self, depth: torch.Tensor, mask: torch.Tensor) -> CanonicalOutput:
        return self.head(super().forward(torch.cat([depth, mask], dim=1)))
