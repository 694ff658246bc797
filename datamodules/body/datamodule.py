"""The body regressor's data: Anny people drawn and rendered on the fly (:mod:`datamodules.body.people`).

Nothing is prepared on disk. ``setup()`` loads the Anny body and draws the fixed splits:

- **train**: an endless :class:`~datamodules.body.replay.ReplayStream` of people of draw ``seed``
  (``draw`` people rendered at a time, each used about ``reuse`` times from a buffer of ``buffer``);
  under DDP each rank draws its own people;
- **val**: ``val_people`` people of draw ``seed + 1``, the same every epoch (the checkpoint monitor);
- **test**: ``test_people`` people of draw ``test_seed`` (1000: the evaluation's held-out draw).

Draws 1000 and 2000 are held out (the evaluation's people and the draw the refinement's step counts
were chosen on): ``seed`` and ``seed + 1`` may not be one of them.

Batches: dicts of ``image (B, 2, S, S)``, ``extras (B, 3)``, ``phenotype (B, 6)``, ``theta (B, D)``,
``rotmat (B, 3, 3)``, ``translation (B, 3)`` float32 (:mod:`datamodules.body.people`). ``S`` and the
crop come from ``preprocess`` (the task's, :class:`lit3d.body_fit.regressor.Preprocess`: the
network's input must be cut the same way in training and use).
"""
from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping
from dataclasses import asdict
from pathlib import Path
from typing import Any

import lightning.pytorch as pl
import torch
from torch.utils.data import DataLoader, Dataset

from datamodules.body.preview import crops_png
from datamodules.body.people import HELD_OUT_SEEDS, Placement, draw_people, shape_distribution
from datamodules.body.replay import ReplayStream
from datamodules.loaders import distributed_world, evaluation_loader
from lit3d.body_fit.model import Body
from lit3d.body_fit.regressor import Preprocess
from lit3d.body_fit.synthetic import Camera

SPLITS = ("val", "test")


class PeopleSet(Dataset):
    """A fixed draw of people (a dict of ``(n, ...)`` tensors) as a map-style dataset of single samples."""

    def __init__(self, people: Mapping[str, torch.Tensor]):
        self.people = dict(people)

    def __len__(self) -> int:
        return len(self.people["image"])

    def __getitem__(self, i: int) -> dict[str, torch.Tensor]:
        return {k: v[i] for k, v in self.people.items()}


class BodyDataModule(pl.LightningDataModule):
    """Rendered Anny people for the body regressor (module doc).

    Args:
        preprocess: :class:`~lit3d.body_fit.regressor.Preprocess` fields (the task's ``preprocess``).
        placement: :class:`~datamodules.body.people.Placement` fields (distance, lateral, sensor, poses).
        batch_size: people per training step (and per validation/test batch).
        draw: people drawn and rendered at a time.
        reuse: training uses of each drawn person (about).
        buffer: people kept in memory.
        val_people, test_people: sizes of the fixed splits.
        seed: the training draw (``seed + 1``: validation).
        test_seed: the test draw (held out from training).
        faust_root: a FAUST folder (``training/registrations`` or ``faust_a``): the evaluator then also
            fits every FAUST scan (``null``: Anny people only).
        num_workers: loader processes of the validation and test splits.
        data_dir: the data folder of the run's config (nothing is written there: the people live in memory).
    """

    def __init__(self, preprocess: Mapping[str, Any] | None = None, placement: Mapping[str, Any] | None = None,
                 batch_size: int = 64, draw: int = 32, reuse: float = 8.0, buffer: int = 20000,
                 val_people: int = 128, test_people: int = 128, seed: int = 7, test_seed: int = 1000,
                 faust_root: str | None = None, num_workers: int = 0, data_dir: str = "data/body_synth"):
        super().__init__()
        self.save_hyperparameters()
        if {seed, seed + 1} & set(HELD_OUT_SEEDS):
            raise ValueError(f"data.seed={seed}: draws {HELD_OUT_SEEDS} are held out for evaluation "
                             f"(training uses seed, validation seed + 1)")
        if test_seed in (seed, seed + 1):
            raise ValueError(f"data.test_seed={test_seed}: the training (seed) or validation (seed + 1) draw")
        self.prep = Preprocess(**dict(preprocess or {}))
        self.placement = Placement(**dict(placement or {}))
        self.batch_size, self.per_draw, self.reuse, self.buffer = batch_size, draw, reuse, buffer
        self.n = {"val": val_people, "test": test_people}
        self.seeds = {"train": seed, "val": seed + 1, "test": test_seed}
        self.faust_root = faust_root
        self.num_workers, self.data_dir = num_workers, data_dir
        # no cache on disk: the settings that decide the people stand for its hashes (run provenance)
        self.manifest = {"config_hash": self.settings_hash(), "manifest_hash": self.settings_hash()}
        self.body = self.cam = self.dist = None
        self.datasets: dict[str, PeopleSet] = {}
        self.drawn = 0  # people of the training draw used so far (the stream's state, saved in checkpoints)
        self._stream: ReplayStream | None = None

    # ------------------------------------------------------------------ drawing
    def anny_body(self) -> Body:
        """The differentiable Anny body the people are drawn with, loaded once (the evaluator fits with it too)."""
        if self.body is None:
            self.body, self.cam = Body(), Camera.default(*self.placement.image)
            self.dist = shape_distribution(self.body)
        return self.body

    def draw(self, seed: int, first: int, n: int) -> dict[str, torch.Tensor]:
        """People ``first .. first + n - 1`` of draw ``seed``, rendered and cropped (module doc)."""
        self.anny_body()
        return draw_people(self.body, self.dist, seed, first, n, self.cam, self.prep, self.placement)

    def _train_draw(self, first: int, n: int) -> dict[str, torch.Tensor]:
        rank, world = distributed_world()
        group = first // max(n, 1)
        return self.draw(self.seeds["train"], (group * world + rank) * n, n)

    def prepare_data(self) -> None:
        """Nothing to prepare: the people are drawn in memory."""

    def setup(self, stage: str | None = None) -> None:
        for split in SPLITS:
            if split not in self.datasets and self.n[split] > 0:
                self.datasets[split] = PeopleSet(self.draw(self.seeds[split], 0, self.n[split]))

    # ------------------------------------------------------------------ loaders
    def train_dataloader(self) -> DataLoader:
        self._stream = ReplayStream(self._train_draw, self.batch_size, self.per_draw, self.reuse, self.buffer,
                                    self.seeds["train"], self.drawn)
        return DataLoader(self._stream, batch_size=None, num_workers=0)

    def val_dataloader(self) -> DataLoader:
        return evaluation_loader(self.datasets["val"], self.batch_size, self.num_workers)

    def test_dataloader(self) -> DataLoader:
        return evaluation_loader(self.datasets["test"], self.batch_size, self.num_workers)

    # ------------------------------------------------------------------ resume
    def state_dict(self) -> dict[str, Any]:
        return {"drawn": int(self._stream.drawn if self._stream is not None else self.drawn)}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.drawn = int(state.get("drawn", 0))

    # ------------------------------------------------------------------ inspection
    def settings_hash(self) -> str:
        """sha256 (16 hex) of what decides the people: draws, placement, crop."""
        key = {"seeds": self.seeds, "n": self.n, "placement": asdict(self.placement), "preprocess": asdict(self.prep)}
        return hashlib.sha256(json.dumps(key, sort_keys=True).encode()).hexdigest()[:16]

    def describe(self) -> dict[str, Any]:
        return {"source": "anny (drawn and rendered on the fly)", "train": "endless", "val": self.n["val"],
                "test": self.n["test"], "seeds": self.seeds, "image_size": self.prep.size,
                "placement": asdict(self.placement), "faust_root": self.faust_root,
                "config_hash": self.settings_hash(), "manifest_hash": self.settings_hash(), "skipped_bad_files": 0}

    def show(self, n: int, path: str | Path, split: str = "val") -> Path:
        """PNG of ``n`` people of ``split`` as the regressor sees them: coverage | relative depth."""
        if split not in self.datasets:
            self.setup()
        people = self.datasets[split].people
        return crops_png({k: v[:n] for k, v in people.items()}, Path(path), title=f"{split} people (draw {self.seeds[split]})")

