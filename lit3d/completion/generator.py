"""3DCascade-GAN generator (thesis fig. 3.1): a cascade of encoder-decoder stages.

Per stage (:class:`CascadeStage`):
    encoder  L x [Conv3d k=4 s=1 'same' -> LeakyReLU(0.2) -> MaxPool 2]   (paper 64,128,256,512: 64^3 -> 4^3)
    FC -> latent (n) -> LatentSelector (top K)  | selector off: FC -> fixed latent of fixed_latent_dim
    FC -> enc[-1] x b^3 (ReLU) -> decoder L x ConvTranspose3d k=4 s=2 p=1 (+ReLU) with skip links
    (concatenation of the stage's pooled encoder maps at matching resolutions).
Intermediate stages end in 1 channel of logits at r^3; stage s > 1 takes
concat(input, sigmoid(stage logits so far)) as input (2, then 3 channels).
The last stage's decoder ends in ``up_channels[0]`` channels at r^3 and adds
``len(up_channels)`` more ConvTranspose3d x2 layers (paper (16, 8): 64^3x16 -> 128^3x8 -> 256^3x1),
and receives global skip links from the stage-1 encoder (concatenated next to its own).
Optional self-attention (``attention="generator"``) on the decoder map nearest ``attention_res``.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import torch
import torch.nn as nn
import torch.nn.functional as F

from lit3d.completion.attention import SelfAttention3d
from lit3d.completion.layers import same_conv, up_conv
from lit3d.completion.selector import LatentSelector


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
        fixed_latent_dim: int | None,
        selector_norm: bool = False,
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
            self.encoder.append(nn.Sequential(same_conv(cin, c), nn.LeakyReLU(0.2, inplace=True), nn.MaxPool3d(2)))
            cin = c
        flat = enc[-1] * self.bottleneck**3
        n = latent_dim if selector else fixed_latent_dim
        self.latent_dim = n
        self.fc_enc = nn.Linear(flat, n)
        self.selector = LatentSelector(n, k, selector_mode, selector_norm) if selector else None
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
            self.decoder.append(up_conv(cin, cout))
            cur = cout
        self.up = nn.ModuleList()
        # input skip: the stage input at r^3 joins the first up-sampling layer (needs up layers)
        self.input_skip = bool(input_skip) and bool(self.up_channels)
        if self.input_skip:
            cur += in_channels
        for i in range(len(self.up_channels)):
            cout = self.up_channels[i + 1] if i + 1 < len(self.up_channels) else 1
            self.up.append(up_conv(cur, cout))
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
        latent = self.fc_enc(feats[-1].flatten(1))
        mask = None
        if self.selector is not None:
            latent, mask = self.selector(latent)
        b = self.bottleneck
        h = F.relu(self.fc_dec(latent)).view(x.shape[0], self.enc_channels[-1], b, b, b)
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
    """Cascade of ``stages`` encoder-decoders (thesis fig. 3.1). Sizes have no defaults: they come
    from the task config (``conf/task/completion.yaml``, ``conf/experiment/completion_*.yaml``).

    forward(x (B, 1, r, r, r) float32 in {0, 1}) -> :class:`GeneratorOutput` with
    ``logits (B, 1, R, R, R)``, R = r * 2**len(up_channels); ``sigmoid(logits)`` is the probability.
    """

    def __init__(
        self,
        *,
        in_res: int,
        stages: int,
        enc_channels: Sequence[int],
        up_channels: Sequence[int],
        latent_dim: int,
        k: int,
        fixed_latent_dim: int | None = None,
        selector: bool = True,
        selector_mode: str = "straight_through",
        selector_norm: bool = False,
        global_skips: bool = True,
        input_skip: bool = False,
        attention: str = "none",
        attention_res: int | None = None,
    ):
        super().__init__()
        if not 1 <= stages <= 3:
            raise ValueError(f"stages={stages}: the cascade has 1, 2 or 3 stages")
        if attention not in ("none", "generator"):
            raise ValueError(f"generator attention '{attention}': use 'none' or 'generator'")
        if attention == "generator" and attention_res is None:
            raise ValueError("generator attention needs attention_res (the decoder map side it goes nearest to)")
        if not selector and fixed_latent_dim is None:
            raise ValueError("selector off needs fixed_latent_dim (the size of the fixed latent code)")
        self.in_res = in_res
        self.use_global_skips = bool(global_skips) and stages > 1
        self.stages = nn.ModuleList()
        for s in range(stages):
            is_last = s == stages - 1
            self.stages.append(CascadeStage(
                in_res=in_res, in_channels=s + 1, enc_channels=enc_channels, latent_dim=latent_dim,
                selector=selector, k=k, selector_mode=selector_mode, fixed_latent_dim=fixed_latent_dim,
                selector_norm=selector_norm,
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
