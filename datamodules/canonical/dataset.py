"""Torch side of the canonical-form data: the pair dataset over the in-memory cache and the
subject-balanced training sampler.

Items (``S = image_size``): ``depth``, ``mask``, ``canon_depth``, ``canon_mask`` ``(1, S, S)``
float32; ``subject`` str, ``subject_idx``, ``pose``, ``view`` int. With ``flip_lr`` (training
only) all four images of an item are mirrored left-right together with probability 1/2.
"""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch
from torch.utils.data import Dataset, WeightedRandomSampler


class PairDataset(Dataset):
    """Indexable pairs from the in-memory cache (see module docstring for the item dict)."""

    def __init__(self, records: list[dict], cache: dict[str, dict], subject_index: dict[str, int],
                 flip_lr: bool = False):
        self.records, self.cache, self.subject_index = records, cache, subject_index
        self.flip_lr = flip_lr  # mirror input and target left-right together with probability 1/2

    def __len__(self):
        return len(self.records)

    def __getitem__(self, i):
        r = self.records[i]
        c = self.cache[r["subject"]]
        pk, ck = f"{r['pose']}_{r['view']}", f"canonical_{r['view']}"
        flip = self.flip_lr and bool(torch.rand(()) < 0.5)
        t = lambda a: torch.from_numpy(np.ascontiguousarray(a[:, ::-1] if flip else a, dtype=np.float32))[None]  # noqa: E731
        return {
            "depth": t(c["depth"][pk]), "mask": t(c["mask"][pk]),
            "canon_depth": t(c["depth"][ck]), "canon_mask": t(c["mask"][ck]),
            "subject": r["subject"], "subject_idx": self.subject_index[r["subject"]],
            "pose": int(r["pose"]), "view": int(r["view"]), "index": i,
        }


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
