"""A labelled PNG of people as the body regressor sees them (``lit3d-data ... --show``)."""
from __future__ import annotations

import io
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import torch
from PIL import Image

from lit3d.body_fit.model import PHENOTYPES
from lit3d.utils.figures import labelled_grid
from lit3d.utils.io import atomic_write_bytes

CELL = 256


def _tile(channel: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """``(S, S)`` values -> ``(CELL, CELL, 3) uint8`` grey, ``lo`` black, ``hi`` white (nearest resize)."""
    grey = np.clip((channel - lo) / max(hi - lo, 1e-6), 0, 1)
    img = Image.fromarray((255 * grey).astype(np.uint8)).resize((CELL, CELL), Image.NEAREST)
    return np.repeat(np.asarray(img)[..., None], 3, 2)


def crops_png(people: Mapping[str, torch.Tensor], path: Path, title: str) -> Path:
    """One row per person: the coverage channel, the relative-depth channel (-1..1 units), and the
    person's height, gender and distance as the label; written atomically to ``path``."""
    rows = []
    for i in range(len(people["image"])):
        img = people["image"][i].float().numpy()
        ex = people["extras"][i].float().numpy()
        ph = dict(zip(PHENOTYPES, people["phenotype"][i].tolist()))
        label = f"person {i}\nbox {ex[0]:.2f} x {ex[1]:.2f} m\nat {ex[2]:.2f} m\n" + \
            "\n".join(f"{k} {ph[k]:.2f}" for k in ("gender", "height") if k in ph)
        rows.append({"label": label, "cells": [_tile(img[0], 0, 1), _tile(img[1], -1, 1)]})
    grid = labelled_grid(rows, ["coverage", "depth - median (units)"], title, cell=CELL)
    buf = io.BytesIO()
    grid.save(buf, format="PNG")
    atomic_write_bytes(path, buf.getvalue())
    return path
