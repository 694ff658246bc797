"""3DCascade-GAN networks of thesis chapter 3 (shape completion from one depth view).

Plain ``nn.Module``s (no Lightning). Every size comes from the config, so the same code runs
at paper scale (64^3 -> 256^3, see :data:`PAPER`) and at a demo scale that trains on a CPU
(16^3 -> 64^3, see :data:`DEMO`).

Tensors (B = batch, r = input grid, R = shape grid = 4 r at both presets):
    partial input  (B, 1, r, r, r) float32 in {0, 1}
    generator      -> GeneratorOutput.logits (B, 1, R, R, R) float; ``sigmoid(logits)`` is the
                      occupancy probability (logits are returned so the BCE runs from logits in fp32)
    critic(partial, shape (B, 1, R, R, R) probabilities in [0, 1]) -> (B,)
    classifier(shape probabilities (B, 1, R, R, R)) -> (B, n_classes) logits

Generator (:class:`CascadeGenerator`), per stage:
    encoder  L x [Conv3d k=4 s=1 'same' -> LeakyReLU(0.2) -> MaxPool 2]   (paper 64,128,256,512: 64^3 -> 4^3)
    FC -> latent (n = 1000) -> LatentSelector (top K = 100)  | selector off: FC -> fixed latent 2000
    FC -> enc[-1] x b^3 (ReLU) -> decoder L x ConvTranspose3d k=4 s=2 p=1 (+ReLU) with skip links
    (concatenation of the stage's pooled encoder maps at matching resolutions).
    Intermediate stages end in 1 channel of logits at r^3; stage s > 1 takes
    concat(input, sigmoid(stage logits so far)) as input (2, then 3 channels).
    The last stage's decoder ends in ``up_channels[0]`` channels at r^3 and adds
    ``len(up_channels)`` more ConvTranspose3d x2 layers (paper (16, 8): 64^3x16 -> 128^3x8 -> 256^3x1),
    and receives global skip links from the stage-1 encoder (concatenated next to its own).
    Optional self-attention (``attention="generator"``) on the decoder map nearest ``attention_res``.

Critic (:class:`Critic`): concat(nearest-upsampled partial, shape) -> N x [Conv3d k=4 s=2 p=1,
LeakyReLU(0.2)] (the last conv linear), no normalisation (WGAN-GP), self-attention after the
layer whose output is ``attention_res``^3, output = per-sample mean of the last feature map
(optionally after the thesis's sigmoid).

Classifier (:class:`ShapeClassifier`): shape max-pooled to ``in_res`` -> [Conv3d k=4 'same',
LeakyReLU, MaxPool 2] while the grid is larger than 4 and channels remain -> Linear -> logits.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import torch
import torch.nn as nn
import torch.nn.functional as F

from lit3d.nets.attention import SelfAttention3d

SELECTOR_MODES = ("straight_through", "literal")
ATTENTION_PLACES = ("discriminator", "generator", "both", "none")

# Thesis sizes (lit3d-summary experiment=completion_paper prints params / memory per component).
PAPER: dict = dict(
    in_res=64,                    # partial input grid
    out_res=256,                  # shape grid; = in_res * 2 ** len(up_channels)
    stages=3,                     # cascade stages 1..3
    enc_channels=[64, 128, 256, 512],
    up_channels=[16, 8],          # last stage: channels at r^3, 2r^3 (then 1 channel at 4r^3)
    latent_dim=1000,              # n
    selector=True,                # dynamic latent selection (off: fixed latent of fixed_latent_dim)
    selector_mode="straight_through",  # or "literal" (thesis eq. 3.1 as written: no gradient to w)
    k=100,                        # K
    fixed_latent_dim=2000,
    global_skips=True,            # stage-1 encoder -> last-stage decoder
    input_skip=True,              # last stage: its r^3 input (partial + earlier stages) -> first up-sampling layer
    attention="discriminator",    # where the 3D self-attention goes: discriminator|generator|both|none
    generator_attention_res=16,
    critic_channels=[32, 64, 128, 256, 512, 512, 512],  # 7 x Conv3d k=4 s=2: 256^3 -> 2^3
    critic_attention_res=16,
    critic_sigmoid=True,          # thesis: sigmoid on the last critic layer (False: plain WGAN critic)
    classifier=True,
    classifier_res=64,            # shape max-pooled to this grid
    classifier_channels=[32, 64, 128, 256],  # 64^3 -> 4^3 (the thesis's 7 layers do not fit 64^3)
    n_classes=4,
)

# Demo scale: 16^3 -> 64^3; one generator + critic step at batch 4 well under 1 s on 2 CPU cores.
DEMO: dict = dict(
    PAPER,
    in_res=16,
    out_res=64,
    enc_channels=[8, 16, 32],
    up_channels=[8, 4],
    latent_dim=128,
    k=32,
    fixed_latent_dim=256,
    generator_attention_res=8,
    critic_channels=[4, 8, 16, 32, 32],       # 64^3 -> 2^3 (few channels at 32^3: the GP's double backward dominates)
    critic_attention_res=8,
    classifier_res=16,
    classifier_channels=[8, 16],              # 16^3 -> 4^3
)

PRESETS = {"paper": PAPER, "demo": DEMO}


def _same_conv(cin: int, cout: int, k: int = 4) -> nn.Sequential:
    """Conv3d k, stride 1, output size = input size (asymmetric zero padding for even k, like 'same')."""
    lo = (k - 1) // 2
    hi = k - 1 - lo
    return nn.Sequential(nn.ConstantPad3d((lo, hi, lo, hi, lo, hi), 0.0), nn.Conv3d(cin, cout, k))


def _up(cin: int, cout: int) -> nn.ConvTranspose3d:
    """ConvTranspose3d k=4 s=2 p=1: doubles every spatial side."""
    return nn.ConvTranspose3d(cin, cout, 4, stride=2, padding=1)


# ---------------------------------------------------------------------------- selector
class LatentSelector(nn.Module):
    """Dynamic latent code selection (thesis 3.2.1, fig. 3.4).

    ``w = sigmoid(FC_n(ReLU(FC_n(l))))``; entries of ``l`` whose ``w`` is among the top ``k`` are
    kept in place, the others are zeroed.

    Modes:
        ``"straight_through"`` (default): forward value ``l * hard``; backward treats the mask as
            ``w``, i.e. ``l * (hard + w - w.detach())``, so the weight net learns.
        ``"literal"``: ``l * hard`` (eq. 3.1 as written; the weight net gets no gradient).

    forward(l (B, n) float) -> (selected (B, n), keep_mask (B, n) float in {0, 1}, k ones per row)
    """

    def __init__(self, n: int, k: int, mode: str = "straight_through"):
        super().__init__()
        if mode not in SELECTOR_MODES:
            raise ValueError(f"selector mode '{mode}' unknown; use one of {SELECTOR_MODES}")
        if not 1 <= k <= n:
            raise ValueError(f"selector k={k} must be in [1, n={n}]")
        self.n, self.k, self.mode = n, k, mode
        self.weight_net = nn.Sequential(nn.Linear(n, n), nn.ReLU(inplace=True), nn.Linear(n, n), nn.Sigmoid())

    def forward(self, l: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        w = self.weight_net(l)
        idx = torch.topk(w, self.k, dim=1).indices
        hard = torch.zeros_like(w).scatter(1, idx, 1.0)
        if self.mode == "straight_through":
            # = l * (hard + w - w.detach()), written so the forward value is exactly l * hard
            return l * hard + l * (w - w.detach()), hard
        return l * hard, hard

    def extra_repr(self) -> str:
        return f"n={self.n}, k={self.k}, mode={self.mode}"


# ---------------------------------------------------------------------------- generator
@dataclass
class GeneratorOutput:
    """logits (B, 1, R, R, R): final shape logits, ``sigmoid(logits)`` = occupancy probability.
    stage_logits: per-stage logits, intermediate ones (B, 1, r, r, r), the last one = ``logits``.
    keep_fraction: scalar, mean fraction of latent entries kept (1.0 without selector)."""

    logits: torch.Tensor
    stage_logits: list[torch.Tensor] = field(default_factory=list)
    keep_fraction: torch.Tensor | None = None


class CascadeStage(nn.Module):
    """One encoder-decoder stage of the cascade.

    forward(x (B, in_channels, r, r, r), global_skips: list of stage-1 pooled encoder maps or None)
        -> (logits (B, 1, r * 2**len(up_channels), ...)^3, pooled encoder maps [(B, enc[i], r/2^(i+1), ...)],
            keep_mask (B, n) or None)
    """

    def __init__(
        self,
        in_res: int,
        in_channels: int,
        enc_channels: Sequence[int],
        latent_dim: int,
        selector: bool,
        k: int,
        selector_mode: str,
        fixed_latent_dim: int,
        up_channels: Sequence[int] = (),
        global_skip_channels: Sequence[int] | None = None,
        attention_res: int | None = None,
        input_skip: bool = False,
    ):
        super().__init__()
        enc = list(enc_channels)
        L = len(enc)
        if in_res % (2**L):
            raise ValueError(f"in_res={in_res} is not divisible by 2^{L} (len(enc_channels)={L})")
        self.in_res, self.L = in_res, L
        self.bottleneck = in_res // 2**L
        self.enc_channels = enc
        self.encoder = nn.ModuleList()
        cin = in_channels
        for c in enc:
            self.encoder.append(nn.Sequential(_same_conv(cin, c), nn.LeakyReLU(0.2, inplace=True), nn.MaxPool3d(2)))
            cin = c
        flat = enc[-1] * self.bottleneck**3
        n = latent_dim if selector else fixed_latent_dim
        self.latent_dim = n
        self.fc_enc = nn.Linear(flat, n)
        self.selector = LatentSelector(n, k, selector_mode) if selector else None
        self.fc_dec = nn.Linear(n, flat)
        gsc = list(global_skip_channels) if global_skip_channels else [0] * L
        # decoder level j works at resolution b * 2^j on a map with cur channels; skip = enc[L-1-j]
        self.attn_level = None
        if attention_res is not None:
            levels = [self.bottleneck * 2**j for j in range(L)]
            self.attn_level = min(range(L), key=lambda j: abs(math.log2(levels[j]) - math.log2(attention_res)))
        self.attn = None
        self.decoder = nn.ModuleList()
        self.up_channels = list(up_channels)
        cur = enc[-1]
        for j in range(L):
            if j == self.attn_level:
                self.attn = SelfAttention3d(cur)
            cin = cur + enc[L - 1 - j] + gsc[L - 1 - j]
            if j < L - 1:
                cout = enc[L - 2 - j]
            else:
                cout = self.up_channels[0] if self.up_channels else 1
            self.decoder.append(_up(cin, cout))
            cur = cout
        self.up = nn.ModuleList()
        # input skip: the stage input at r^3 joins the first up-sampling layer (needs up layers)
        self.input_skip = bool(input_skip) and bool(self.up_channels)
        if self.input_skip:
            cur += in_channels
        for i in range(len(self.up_channels)):
            cout = self.up_channels[i + 1] if i + 1 < len(self.up_channels) else 1
            self.up.append(_up(cur, cout))
            cur = cout

    @property
    def out_res(self) -> int:
        return self.in_res * 2 ** len(self.up_channels)

    def encode(self, x: torch.Tensor) -> list[torch.Tensor]:
        feats = []
        for layer in self.encoder:
            x = layer(x)
            feats.append(x)
        return feats

    def forward(self, x: torch.Tensor, global_skips: list[torch.Tensor] | None = None):
        feats = self.encode(x)
        l = self.fc_enc(feats[-1].flatten(1))
        mask = None
        if self.selector is not None:
            l, mask = self.selector(l)
        b = self.bottleneck
        h = F.relu(self.fc_dec(l)).view(x.shape[0], self.enc_channels[-1], b, b, b)
        last = len(self.decoder) - 1
        for j, deconv in enumerate(self.decoder):
            if j == self.attn_level:
                h = self.attn(h)
            parts = [h, feats[self.L - 1 - j]]
            if global_skips is not None:
                parts.append(global_skips[self.L - 1 - j])
            h = deconv(torch.cat(parts, 1))
            if j < last or self.up:
                h = F.relu(h)
        if self.input_skip:
            h = torch.cat([h, x], 1)
        for i, up in enumerate(self.up):
            h = up(h)
            if i < len(self.up) - 1:
                h = F.relu(h)
        return h, feats, mask


class CascadeGenerator(nn.Module):
    """Cascade of ``stages`` encoder-decoders (thesis fig. 3.1).

    forward(x (B, 1, r, r, r) float32 in {0, 1}) -> :class:`GeneratorOutput` with
    ``logits (B, 1, R, R, R)``, R = r * 2**len(up_channels); ``sigmoid(logits)`` is the probability.
    """

    def __init__(
        self,
        in_res: int = 64,
        stages: int = 3,
        enc_channels: Sequence[int] = (64, 128, 256, 512),
        up_channels: Sequence[int] = (16, 8),
        latent_dim: int = 1000,
        selector: bool = True,
        k: int = 100,
        selector_mode: str = "straight_through",
        fixed_latent_dim: int = 2000,
        global_skips: bool = True,
        input_skip: bool = False,
        attention: str = "none",
        attention_res: int = 16,
    ):
        super().__init__()
        if not 1 <= stages <= 3:
            raise ValueError(f"stages={stages}: the cascade has 1, 2 or 3 stages")
        if attention not in ("none", "generator"):
            raise ValueError(f"generator attention '{attention}': use 'none' or 'generator'")
        self.in_res = in_res
        self.use_global_skips = bool(global_skips) and stages > 1
        self.stages = nn.ModuleList()
        for s in range(stages):
            is_last = s == stages - 1
            self.stages.append(CascadeStage(
                in_res=in_res, in_channels=s + 1, enc_channels=enc_channels, latent_dim=latent_dim,
                selector=selector, k=k, selector_mode=selector_mode, fixed_latent_dim=fixed_latent_dim,
                up_channels=up_channels if is_last else (),
                global_skip_channels=enc_channels if (is_last and self.use_global_skips) else None,
                attention_res=attention_res if attention == "generator" else None,
                input_skip=input_skip and is_last,
            ))
        self.out_res = self.stages[-1].out_res

    def forward(self, x: torch.Tensor) -> GeneratorOutput:
        inputs = [x]
        stage_logits, masks = [], []
        first_feats = None
        n = len(self.stages)
        for s, stage in enumerate(self.stages):
            gs = first_feats if (s == n - 1 and self.use_global_skips) else None
            logits, feats, mask = stage(torch.cat(inputs, 1), gs)
            if s == 0:
                first_feats = feats
            stage_logits.append(logits)
            if mask is not None:
                masks.append(mask)
            if s < n - 1:
                inputs.append(torch.sigmoid(logits))
        if masks:
            keep = torch.stack([m.float().mean() for m in masks]).mean()
        else:
            keep = torch.ones((), device=x.device)
        return GeneratorOutput(logits=stage_logits[-1], stage_logits=stage_logits, keep_fraction=keep)


# ---------------------------------------------------------------------------- critic
class Critic(nn.Module):
    """WGAN-GP critic on (partial input, shape) pairs (thesis fig. 3.2).

    forward(partial (B, 1, r, r, r) in {0, 1}, shape (B, 1, R, R, R) probabilities) -> (B,)
    The partial grid is nearest-upsampled to R^3 and concatenated (2 channels). Each of the
    ``len(channels)`` layers is Conv3d k=4 s=2 p=1 followed by LeakyReLU(0.2), except the last
    (linear); self-attention follows the layer whose output side equals ``attention_res``.
    Output = per-sample mean of the last map, after a sigmoid when ``sigmoid=True`` (thesis).
    """

    def __init__(
        self,
        in_res: int = 256,
        channels: Sequence[int] = (32, 64, 128, 256, 512, 512, 512),
        attention_res: int = 16,
        use_attention: bool = True,
        sigmoid: bool = False,
    ):
        super().__init__()
        channels = list(channels)
        if in_res % 2 ** len(channels):
            raise ValueError(f"critic: in_res={in_res} cannot be halved {len(channels)} times")
        self.in_res, self.sigmoid = in_res, sigmoid
        self.layers = nn.ModuleList()
        self.attn_after: int | None = None
        self.attn = None
        cin, res = 2, in_res
        for i, c in enumerate(channels):
            res //= 2
            last = i == len(channels) - 1
            self.layers.append(nn.Sequential(nn.Conv3d(cin, c, 4, stride=2, padding=1),
                                             *( [] if last else [nn.LeakyReLU(0.2, inplace=True)] )))
            if use_attention and res == attention_res and not last and self.attn is None:
                self.attn_after, self.attn = i, SelfAttention3d(c)
            cin = c
        if use_attention and self.attn is None:
            raise ValueError(f"critic: no layer output is {attention_res}^3 (in_res={in_res}, {len(channels)} layers)")

    def forward(self, partial: torch.Tensor, shape: torch.Tensor) -> torch.Tensor:
        p = partial.to(shape.dtype)
        if p.shape[-3:] != shape.shape[-3:]:
            p = F.interpolate(p, size=shape.shape[-3:], mode="nearest")
        h = torch.cat([p, shape], 1)
        for i, layer in enumerate(self.layers):
            h = layer(h)
            if i == self.attn_after:
                h = self.attn(h)
        if self.sigmoid:
            h = torch.sigmoid(h)
        return h.flatten(1).mean(1)


# ---------------------------------------------------------------------------- classifier
class ShapeClassifier(nn.Module):
    """Auxiliary category classifier (thesis fig. 3.3).

    forward(shape (B, 1, R, R, R) probabilities) -> (B, n_classes) logits. The shape is
    max-pooled to ``in_res``^3, then [Conv3d k=4 s=1 'same', LeakyReLU(0.2), MaxPool 2] while the
    grid side is above 4 and channels remain, then Linear.
    """

    def __init__(self, in_res: int = 64, channels: Sequence[int] = (32, 64, 128, 256), n_classes: int = 4):
        super().__init__()
        self.in_res = in_res
        layers, cin, res = [], 1, in_res
        for c in channels:
            if res <= 4 or res % 2:
                break
            layers += [_same_conv(cin, c), nn.LeakyReLU(0.2, inplace=True), nn.MaxPool3d(2)]
            cin, res = c, res // 2
        self.features = nn.Sequential(*layers)
        self.head = nn.Linear(cin * res**3, n_classes)

    def forward(self, shape: torch.Tensor) -> torch.Tensor:
        if shape.shape[-1] != self.in_res:
            if shape.shape[-1] % self.in_res:
                raise ValueError(f"classifier: grid {shape.shape[-1]} is not a multiple of in_res={self.in_res}")
            shape = F.max_pool3d(shape, shape.shape[-1] // self.in_res)
        return self.head(self.features(shape).flatten(1))


# ---------------------------------------------------------------------------- factory
def resolve_config(cfg: dict | None) -> dict:
    """Merge ``cfg`` over its preset (``cfg["preset"]``: "paper" (default) or "demo"); validate keys."""
    cfg = dict(cfg or {})
    preset = cfg.pop("preset", "paper")
    if preset not in PRESETS:
        raise ValueError(f"unknown completion preset '{preset}' (paper, demo)")
    unknown = sorted(set(cfg) - set(PAPER))
    if unknown:
        raise ValueError(f"unknown completion net config keys {unknown}; known: {sorted(PAPER)}")
    out = {**PRESETS[preset], **cfg}
    if out["attention"] not in ATTENTION_PLACES:
        raise ValueError(f"attention='{out['attention']}' unknown; use one of {ATTENTION_PLACES}")
    expect = out["in_res"] * 2 ** len(out["up_channels"])
    if out["out_res"] != expect:
        raise ValueError(f"out_res={out['out_res']} but in_res * 2**len(up_channels) = {expect}")
    return out


def generator_kwargs(cfg: dict) -> dict:
    c = resolve_config(cfg)
    return dict(
        in_res=c["in_res"], stages=c["stages"], enc_channels=list(c["enc_channels"]),
        up_channels=list(c["up_channels"]), latent_dim=c["latent_dim"], selector=bool(c["selector"]),
        k=c["k"], selector_mode=c["selector_mode"], fixed_latent_dim=c["fixed_latent_dim"],
        global_skips=bool(c["global_skips"]),
        input_skip=bool(c["input_skip"]),
        attention="generator" if c["attention"] in ("generator", "both") else "none",
        attention_res=c["generator_attention_res"],
    )


def build_completion_nets(cfg: dict | None) -> dict[str, nn.Module]:
    """Build ``{"generator", "critic"[, "classifier"]}`` from a plain (nested-free) dict.

    ``cfg`` keys are those of :data:`PAPER`; missing keys come from the preset named by
    ``cfg["preset"]`` ("paper" default, or "demo"). Ablation switches: ``stages`` (1..3),
    ``selector`` (bool), ``selector_mode``, ``k``, ``attention`` (discriminator|generator|both|none),
    ``classifier`` (bool), ``critic_sigmoid`` (bool).
    """
    c = resolve_config(cfg)
    nets: dict[str, nn.Module] = {
        "generator": CascadeGenerator(**generator_kwargs(c)),
        "critic": Critic(
            in_res=c["out_res"], channels=list(c["critic_channels"]), attention_res=c["critic_attention_res"],
            use_attention=c["attention"] in ("discriminator", "both"), sigmoid=bool(c["critic_sigmoid"]),
        ),
    }
    if c["classifier"]:
        nets["classifier"] = ShapeClassifier(c["classifier_res"], list(c["classifier_channels"]), c["n_classes"])
    return nets
