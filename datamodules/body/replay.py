"""The body regressor's training stream: people drawn in groups into a replay buffer in memory,
training batches sampled from it (each person used about ``reuse`` times; nothing is cached on disk)."""
from __future__ import annotations

from collections.abc import Callable, Iterator

import torch
from torch.utils.data import IterableDataset


class ReplayBuffer:
    """A ring of at most ``cap`` samples (dicts of ``(n, ...)`` tensors), images kept as float16."""

    def __init__(self, cap: int):
        self.cap, self.n, self.at, self.data = cap, 0, 0, {}

    def add(self, batch: dict[str, torch.Tensor]) -> None:
        m = len(batch["image"])
        if not self.data:
            self.data = {k: torch.zeros((self.cap, *v.shape[1:]), dtype=torch.float16 if k == "image" else v.dtype)
                         for k, v in batch.items()}
        idx = (self.at + torch.arange(m)) % self.cap
        for k, v in batch.items():
            self.data[k][idx] = v.to(self.data[k].dtype)
        self.at, self.n = (self.at + m) % self.cap, min(self.n + m, self.cap)

    def sample(self, b: int, gen: torch.Generator) -> dict[str, torch.Tensor]:
        """``min(b, n)`` samples drawn uniformly with replacement, as float32 (images too)."""
        idx = torch.randint(self.n, (min(b, self.n),), generator=gen)
        return {k: v[idx].float() for k, v in self.data.items()}


class ReplayStream(IterableDataset):
    """Endless training batches: ``draw(first, n)`` people at a time into a :class:`ReplayBuffer` of
    ``buffer`` people, then about ``reuse * drawn / batch_size`` batches of ``batch_size`` sampled from
    it. ``drawn`` (how many people were drawn so far) is the stream's state: a resumed run starts from
    the next person, not the first (:meth:`datamodules.body.BodyDataModule.state_dict`)."""

    def __init__(self, draw: Callable[[int, int], dict[str, torch.Tensor]], batch_size: int, per_draw: int,
                 reuse: float, buffer: int, seed: int, drawn: int = 0):
        self.draw, self.batch_size, self.per_draw, self.reuse = draw, batch_size, per_draw, reuse
        self.buffer, self.seed, self.drawn = buffer, seed, drawn

    def __iter__(self) -> Iterator[dict[str, torch.Tensor]]:
        buf, gen = ReplayBuffer(self.buffer), torch.Generator().manual_seed(self.seed + self.drawn)
        credit = 0.0
        while True:
            people = self.draw(self.drawn, self.per_draw)
            self.drawn += self.per_draw
            buf.add(people)
            credit += self.reuse * len(people["image"]) / self.batch_size
            while credit >= 1:
                credit -= 1
                yield buf.sample(self.batch_size, gen)
