"""The canonical net's parts as frozen dataclasses, one per node of ``task.net``
(:class:`~lit3d.canonical.nets.CanonicalNet`):

    task.net.lfe             the local feature extractor (:class:`LFESettings`)
    task.net.msfe            the multi-scale feature extractor and its fuser (:class:`MSFESettings`)
    task.net.reconstruction.kind  the trunk under the head (:class:`ReconstructionSettings`)
    task.net.head.kind            what draws the canonical form (:class:`HeadSettings`)

:func:`lit3d.canonical.settings.parse` turns a node into its dataclass (``parse(LFESettings, node, "net.lfe")``);
sequences become tuples.
"""
from __future__ import annotations

from dataclasses import dataclass

HEADS = ("redraw", "warp")
RECONSTRUCTIONS = ("downup", "unet")


@dataclass(frozen=True)
class LFESettings:
    """``use``: the LFE's ``out`` channels join the features (conv ``channels``); false: dropped."""

    channels: tuple[int, ...]
    out: int
    use: bool = True

    def __post_init__(self):
        object.__setattr__(self, "channels", tuple(self.channels))


@dataclass(frozen=True)
class MSFESettings:
    """``use``: three dilated encoders (``channels``, pooled to ``grid`` x ``grid``), a fuser MLP (``fuser_hidden``
    -> ``fuser_out``, the latent) and a decoder (``dec_channels``) give ``out`` channels; false: dropped."""

    channels: tuple[int, ...]
    grid: int
    fuser_hidden: int
    fuser_out: int
    dec_channels: tuple[int, ...]
    out: int
    use: bool = True

    def __post_init__(self):
        object.__setattr__(self, "channels", tuple(self.channels))
        object.__setattr__(self, "dec_channels", tuple(self.dec_channels))


@dataclass(frozen=True)
class ReconstructionSettings:
    """``kind``: ``downup`` (the thesis's encoder-decoder, no skips) or ``unet`` (skip connections), of
    ``channels`` per level."""

    channels: tuple[int, ...]
    kind: str = "downup"

    def __post_init__(self):
        object.__setattr__(self, "channels", tuple(self.channels))
        if self.kind not in RECONSTRUCTIONS:
            raise ValueError(f"unknown canonical reconstruction '{self.kind}' ({', '.join(RECONSTRUCTIONS)})")


@dataclass(frozen=True)
class HeadSettings:
    """``kind``: ``redraw`` (a 1x1 conv draws depth and mask) or ``warp`` (moves the posed pixels by a backward
    flow, :class:`~lit3d.canonical.warp.WarpHead`, of ``hidden`` channels)."""

    kind: str = "redraw"
    hidden: int | None = None

    def __post_init__(self):
        if self.kind not in HEADS:
            raise ValueError(f"unknown canonical net head '{self.kind}' ({', '.join(HEADS)})")
        if self.kind == "warp" and self.hidden is None:
            raise ValueError(f"the {self.kind} head needs its width: set task.net.head.hidden")

