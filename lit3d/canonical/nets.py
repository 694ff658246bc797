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

import math
from collections.abc import Sequence
from dataclasses import dataclass

import torch
import torch.nn as nn
import torch.nn.functional as F

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

    def __init__(self, cin: int = 2, out: int = 1, channels: Sequence[int] = (32, 64, 128)):
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

    def __init__(self, cin: int, out: int = 1, channels: Sequence[int] = (16, 16, 10), grid: int = 40,
                 fuser_hidden: int = 500, fuser_out: int = 500,
                 dec_channels: Sequence[int] = (256, 128, 64, 32, 16, 8), dilations: Sequence[int] = DILATIONS,
                 image_size: int = 500):
        super().__init__()
        self.encoders = nn.ModuleList(DilatedEncoder(cin, channels, d, grid) for d in dilations)
        self.latent_dim = sum(e.latent_dim for e in self.encoders)
        self.fuser = nn.Sequential(nn.Linear(self.latent_dim, fuser_hidden), nn.LeakyReLU(0.2),
                                   nn.Linear(fuser_hidden, fuser_out), nn.LeakyReLU(0.2))
        dec, prev = [], fuser_out
        chans = list(dec_channels) + [out]
        assert len(chans) == len(MSFE_KERNELS), f"msfe_dec_channels needs {len(MSFE_KERNELS) - 1} entries"
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


@dataclass
class CanonicalOutput:
    """Predicted canonical depth ``(B,1,H,W)`` in [0,1], mask probability and mask logits ``(B,1,H,W)``;
    ``latent``: the MSFE's fused latent ``(B, fuser_out)`` (None without an MSFE, and for the U-Net)."""

    depth: torch.Tensor
    mask: torch.Tensor
    mask_logits: torch.Tensor
    latent: torch.Tensor | None = None


class _Head(nn.Module):
    """1x1 conv -> depth (sigmoid) and mask logits."""

    def __init__(self, cin: int):
        super().__init__()
        self.conv = nn.Conv2d(cin, 2, 1)

    def forward(self, h: torch.Tensor) -> CanonicalOutput:
        o = self.conv(h)
        logits = o[:, 1:2]
        return CanonicalOutput(depth=torch.sigmoid(o[:, 0:1]), mask=torch.sigmoid(logits), mask_logits=logits)


class CanonicalNet(nn.Module):
    """LFE -> MSFE -> reconstruction (thesis Fig. 5.1), with ablation switches.

    ``use_lfe=False`` drops the LFE (the MSFE and the reconstruction see depth+mask only);
    ``use_msfe=False`` drops the MSFE. Reconstruction input = [depth, mask, Y_LFE, Y_MSFE].
    """

    def __init__(self, image_size: int = 128, use_lfe: bool = True, use_msfe: bool = True,
                 lfe_channels: Sequence[int] = (32, 64, 128), lfe_out: int = 1,
                 msfe_channels: Sequence[int] = (16, 16, 10), msfe_grid: int = 40, fuser_hidden: int = 500,
                 fuser_out: int = 500, msfe_dec_channels: Sequence[int] = (256, 128, 64, 32, 16, 8),
                 msfe_out: int = 1, rec_channels: Sequence[int] = (32, 64, 128)):
        super().__init__()
        self.image_size = image_size
        self.lfe = LFE(2, lfe_out, lfe_channels) if use_lfe else None
        c = 2 + (lfe_out if use_lfe else 0)
        self.msfe = MSFE(c, msfe_out, msfe_channels, msfe_grid, fuser_hidden, fuser_out, msfe_dec_channels,
                         image_size=image_size) if use_msfe else None
        c += msfe_out if use_msfe else 0
        hidden = max(rec_channels[0] // 2, 4)
        self.reconstruction = DownUp(c, hidden, rec_channels, up_act="leaky", final_act=True)
        self.head = _Head(hidden + 2)  # the input is given to the head again (skip link)

    def forward(self, depth: torch.Tensor, mask: torch.Tensor) -> CanonicalOutput:
        x = torch.cat([depth, mask], dim=1)
        feats, latent = [x], None
        if self.lfe is not None:
            feats.append(self.lfe(x))
        if self.msfe is not None:
            latent = self.msfe.encode(torch.cat(feats, dim=1))
            feats.append(self.msfe.decode(latent, x.shape[-2:]))
        h = self.reconstruction(torch.cat(feats, dim=1))
        out = self.head(torch.cat([h, x], dim=1))
        out.latent = latent
        return out


class UNet(nn.Module):
    """Plain U-Net baseline: ``(depth, mask)`` -> ``CanonicalOutput`` with skip connections.

    Pads the input to a multiple of ``2**len(channels)`` and crops back (size-agnostic).
    """

    def __init__(self, channels: Sequence[int] = (16, 32, 64, 128), image_size: int = 128):
        super().__init__()
        self.image_size = image_size
        ch = list(channels)
        self.enc = nn.ModuleList()
        prev = 2
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
        self.head = _Head(prev)
        self.factor = 2 ** len(ch)

    def forward(self, depth: torch.Tensor, mask: torch.Tensor) -> CanonicalOutput:
        x = torch.cat([depth, mask], dim=1)
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
        out = self.head(x)
        return CanonicalOutput(out.depth[..., :H, :W], out.mask[..., :H, :W], out.mask_logits[..., :H, :W])


INITS = ("he", "torch")
LEAKY_SLOPE = 0.2


def he_init_(net: nn.Module) -> nn.Module:
    """He (fan-in) initialisation for LeakyReLU(0.2) of every conv, transposed conv and linear layer,
    biases zero; in place, returns ``net``.

    A transposed convolution of stride ``s`` feeds each output pixel from ``cin * k^2 / s^2`` inputs
    (not ``cin * k^2``), so its fan-in is counted that way. Why not PyTorch's default: measured on
    TOSCA (README "Real TOSCA"), the default's per-layer gain of about 1/sqrt(3) shrinks the MSFE's
    12 layers so far that its output is the same image for every input at initialisation (spread
    over a batch 4e-8, its biases alone), the global path learns slowly and after 750 steps the net
    still did not fit its own training masks (IoU .5); with this init the spread is 6e-2 and the
    training masks reach IoU .98 in 600 steps.
    """
    gain = nn.init.calculate_gain("leaky_relu", LEAKY_SLOPE)
    for m in net.modules():
        if isinstance(m, (nn.Conv2d, nn.Linear)):
            nn.init.kaiming_normal_(m.weight, a=LEAKY_SLOPE, nonlinearity="leaky_relu")
        elif isinstance(m, nn.ConvTranspose2d):
            cin, k = m.weight.shape[0], m.weight.shape[2] * m.weight.shape[3]
            fan_in = cin * k / (m.stride[0] * m.stride[1])
            nn.init.normal_(m.weight, 0.0, gain / math.sqrt(fan_in))
        else:
            continue
        if m.bias is not None:
            nn.init.zeros_(m.bias)
    return net


def build_canonical_net(net: dict) -> nn.Module:
    """Build from a plain dict: ``{"kind": "canonical"|"unet"|"recall", "init": "he"|"torch", **kwargs}``
    (``init``: :func:`he_init_`, or PyTorch's default layer initialisation; ``recall``:
    :class:`lit3d.canonical.recall.SubjectRecallNet`, sized by ``recall_channels`` and ``n_subjects``)."""
    net = dict(net)
    kind = net.pop("kind", "canonical")
    init = net.pop("init", "torch")
    if init not in INITS:
        raise ValueError(f"unknown canonical net init '{init}' ({', '.join(INITS)})")
    if kind == "canonical":
        net.pop("unet_channels", None)
        net.pop("recall_channels", None)
        model = CanonicalNet(**net)
    elif kind == "unet":
        keep = {k: v for k, v in net.items() if k in ("channels", "image_size")}
        if "unet_channels" in net:
            keep["channels"] = net["unet_channels"]
        model = UNet(**keep)
    elif kind == "recall":
        from lit3d.canonical.recall import SubjectRecallNet  # imports this module

        model = SubjectRecallNet(int(net.get("n_subjects", 0)), int(net.get("image_size", 128)),
                                 net.get("recall_channels", (16, 32, 64, 128)))
    else:
        raise ValueError(f"unknown canonical net kind '{kind}' (canonical, unet, recall)")
    return he_init_(model) if init == "he" else model


def summarize(net: nn.Module, image_size: int) -> list[dict]:
    """Per-component rows (name, params, output shape) for ``lit3d-summary``; works on the meta device."""
    dev = next(net.parameters()).device
    d = torch.zeros(1, 1, image_size, image_size, device=dev)
    m = torch.zeros_like(d)
    x = torch.cat([d, m], 1)
    rows = []
    feats = [x]

    def count(mod):
        return sum(p.numel() for p in mod.parameters())

    if isinstance(net, CanonicalNet):
        if net.lfe is not None:
            y = net.lfe(x)
            feats.append(y)
            rows.append({"component": "LFE", "params": count(net.lfe), "output": tuple(y.shape)})
        if net.msfe is not None:
            inp = torch.cat(feats, 1)
            for i, e in enumerate(net.msfe.encoders):
                z = e(inp)
                rows.append({"component": f"MSFE encoder d={DILATIONS[i]}", "params": count(e), "output": tuple(z.shape)})
            rows.append({"component": "MSFE fuser", "params": count(net.msfe.fuser),
                         "output": (1, net.msfe.fuser[-2].out_features), "input": (1, net.msfe.latent_dim)})
            y = net.msfe(inp)
            feats.append(y)
            rows.append({"component": "MSFE decoder", "params": count(net.msfe.decoder), "output": tuple(y.shape)})
        net.reconstruction(torch.cat(feats, 1))  # checks that the features fit its input channels
        rows.append({"component": "reconstruction", "params": count(net.reconstruction) + count(net.head),
                     "output": (1, 2, image_size, image_size)})
    else:
        rows.append({"component": type(net).__name__, "params": count(net), "output": (1, 2, image_size, image_size)})
    rows.append({"component": "total", "params": count(net), "output": (1, 2, image_size, image_size)})
    return rows
