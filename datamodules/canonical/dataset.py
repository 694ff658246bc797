"""Torch side of the canonical-form data: the pair dataset over the in-memory cache and the
subject-balanced training sampler.

Items (``S = image_size``): ``depth``, ``mask``, ``canon_depth``, ``canon_mask`` ``(1, S, S)``
float32; ``subject`` str, ``subject_idx``, ``pose``, ``view`` int; ``flow`` ``(2, S, S)`` (backward
flow in pixels, :mod:`datamodules.canonical.flow`), ``vis`` ``(1, S, S)`` float32 and ``has_flow``
bool (zeros and False for an item without targets, or whose input is rolled or mirrored without its
target). With ``flip_lr`` (training only) the posed images of an item are mirrored left-right with probability
1/2, and the canonical images with them only when ``flip_target`` (the camera convention decides, see
:class:`CanonicalPairDataset`).
"""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch
from torch.utils.data import Dataset, WeightedRandomSampler


class CanonicalPairDataset(Dataset):
    """Indexable pairs from the in-memory cache (see module docstring for the item dict).

    ``flip_lr``: mirror the posed input left-right with probability 1/2. ``flip_target``: mirror
    the canonical target with it. That is right when input and target share one camera
    (``view_mode=fixed``: the mirrored subject's canonical form, seen by the same camera, is the
    mirrored target). It is wrong with ``view_mode=broadside``, where the target's view is set by
    the canonical shape alone (its own broadside rule), so every item of a subject has the same
    target whatever the input looks like, and the evaluation expects exactly that image: a mirrored
    input still shows the same (bilaterally symmetric) subject, whose target is the unmirrored
    canonical image. A mirrored target there is a view the rule never gives (a quadruped facing the
    other way) and, since the posed broadside orientation agrees with the canonical one for only
    about half the TOSCA poses, the net cannot tell from the input which of the two to draw.
    ``mirror_view`` (broadside with several azimuths): view index -> the index of the view at the
    negated azimuth offset; a mirrored input of view ``v`` then gets the canonical image of
    ``mirror_view[v]`` (a mirrored turn to the left is a turn to the right). Missing: the same view.
    ``roll_deg``: the posed input (depth and mask together, nearest neighbour) turned in the image
    plane by an angle drawn uniformly from [-roll_deg, roll_deg] about the image centre (a rolled
    camera); the target stays.
    """

    def __init__(self, records: list[dict], cache: dict[str, dict], subject_index: dict[str, int],
                 flip_lr: bool = False, flip_target: bool = True, mirror_view: dict[int, int] | None = None,
                 roll_deg: float = 0.0):
        self.records, self.cache, self.subject_index = records, cache, subject_index
        self.flip_lr = flip_lr  # mirror the input left-right with probability 1/2
        self.flip_target = flip_target  # ... and the canonical target with it (same camera only)
        self.mirror_view = dict(mirror_view or {})
        self.roll_deg = float(roll_deg)

    def __len__(self):
        return len(self.records)

    def __getitem__(self, i):
        r = self.records[i]
        c = self.cache[r["subject"]]
        flip = self.flip_lr and bool(torch.rand(()) < 0.5)
        flip_canon = flip and self.flip_target
        target_view = self.mirror_view.get(r["view"], r["view"]) if flip and not self.flip_target else r["view"]
        pk, ck = f"{r['pose']}_{r['view']}", f"canonical_{target_view}"

        def t(a, mirror):
            return torch.from_numpy(np.ascontiguousarray(a[:, ::-1] if mirror else a, dtype=np.float32))[None]

        depth, mask = t(c["depth"][pk], flip), t(c["mask"][pk], flip)
        angle = float((torch.rand(()) * 2 - 1) * self.roll_deg) if self.roll_deg else 0.0
        if angle:
            depth, mask = roll(depth, mask, angle)
        # flow targets hold only when input and target moved together (not rolled; mirrored both or neither)
        has_flow = pk in c.get("flow", {}) and not angle and flip == flip_canon and target_view == r["view"]
        if has_flow:
            flow = c["flow"][pk].astype(np.float32)
            if flip:  # mirrored pair: the flow of the mirrored image, its x component negated
                flow = flow[:, :, ::-1] * np.array([-1.0, 1.0], np.float32)[:, None, None]
            flow, vis = torch.from_numpy(np.ascontiguousarray(flow)), t(c["vis"][pk], flip)
        else:
            size = depth.shape[-1]
            flow, vis = torch.zeros(2, size, size), torch.zeros(1, size, size)
        return {
            "depth": depth, "mask": mask,
            "canon_depth": t(c["depth"][ck], flip_canon), "canon_mask": t(c["mask"][ck], flip_canon),
            "subject": r["subject"], "subject_idx": self.subject_index[r["subject"]],
            "pose": int(r["pose"]), "view": int(r["view"]), "index": i,
            "flow": flow, "vis": vis, "has_flow": has_flow,
        }

    def canonical_templates(self, view: int = 0) -> tuple[torch.Tensor, torch.Tensor]:
        """Every subject's canonical depth and mask seen from view ``view``, ``(K, 1, S, S)`` float32 each,
        row k = the subject with index k (the closed-set recall net's templates)."""
        by_index = sorted(self.subject_index.items(), key=lambda kv: kv[1])
        if [i for _, i in by_index] != list(range(len(by_index))):
            raise ValueError(f"subject indices are not 0..K-1: {dict(by_index)}")
        key = f"canonical_{int(view)}"
        depth = [self.cache[s]["depth"][key] for s, _ in by_index]
        mask = [self.cache[s]["mask"][key] for s, _ in by_index]
        return (torch.from_numpy(np.stack(depth).astype(np.float32))[:, None],
                torch.from_numpy(np.stack(mask).astype(np.float32))[:, None])


def mirror_views(azimuths: Sequence[float]) -> dict[int, int]:
    """View index -> index of the view at the negated azimuth offset (itself when there is none)."""
    az = [float(a) for a in azimuths]
    return {i: next((j for j, b in enumerate(az) if abs(b + a) < 1e-6), i) for i, a in enumerate(az)}


def roll(depth: torch.Tensor, mask: torch.Tensor, degrees: float) -> tuple[torch.Tensor, torch.Tensor]:
    """``(1, S, S)`` depth and mask turned by ``degrees`` (counter-clockwise) about the image centre,
    nearest neighbour (no depth is mixed with the background), zeros where the turn uncovers; the
    depth is kept only inside the turned mask."""
    from kornia.geometry.transform import rotate

    x = torch.cat([depth, mask], 0)[None]
    out = rotate(x, torch.tensor([float(degrees)]), mode="nearest", padding_mode="zeros", align_corners=True)[0]
    m = (out[1:2] > 0.5).float()
    return out[0:1] * m, m


def subject_balanced_sampler(records: Sequence[dict], seed: int) -> WeightedRandomSampler:
    """Draws ``len(records)`` items per epoch with replacement, each subject equally often
    (item weight 1 / items of its subject): a subject with many poses (TOSCA's michael has 20,
    wolf 3) no longer dominates the canonical shape the network learns."""
    counts: dict[str, int] = {}
    for r in records:
        counts[r["subject"]] = counts.get(r["subject"], 0) + 1
    weights = torch.tensor([1.0 / counts[r["subject"]] for r in records], dtype=torch.double)
    return WeightedRandomSampler(weights, num_samples=len(records), replacement=True,
                                 generator=torch.Generator().manual_seed(int(seed)))
