"""The bad files of tests/cli/test_bad_inputs.py's table: each ``writer(tmp_path) -> (argument, named)``
writes real bad file(s) and says what the entry point gets and which file its message must name."""
from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch

from datamodules.canonical import CanonicalDataModule
from datamodules.completion.recgan import RecganPair
from tests.helpers.files import liris_epfl


def _write(path: Path, data: bytes | str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    (path.write_bytes if isinstance(data, bytes) else path.write_text)(data)
    return path


def _file(name: str, data: bytes | str):
    def write(tmp: Path):
        p = _write(tmp / name, data)
        return p, str(p)
    return write


def _npz(name: str, **arrays):
    def write(tmp: Path):
        p = tmp / name
        np.savez(p, **arrays)
        return p, str(p)
    return write


def _dir(name: str):
    def write(tmp: Path):
        (tmp / name).mkdir()
        return tmp / name, str(tmp / name)
    return write


def _missing(name: str):
    return lambda tmp: (tmp / name, str(tmp / name))


PLY_HEAD = ("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
            "element face 1\nproperty list uchar int vertex_indices\nend_header\n")
GARBAGE = bytes(range(256)) * 16
BOX = np.zeros((8, 8, 8, 1), np.int8)
BOX[2:6, 2:6, 2:6] = 1


def _pair(inp: np.ndarray, tgt: np.ndarray, bad: str):
    """A 3D-RecGAN++ input/target pair; ``bad`` ("input" | "target") is the file the message must name."""
    def write(tmp: Path):
        paths = {}
        for kind, arr in (("input", inp), ("target", tgt)):
            paths[kind] = tmp / f"P1_03001627_chair/train_125_{'25d' if kind == 'input' else '3d'}_vox256/aa_0_0_0.npz"
            paths[kind].parent.mkdir(parents=True, exist_ok=True)
            np.savez_compressed(paths[kind], arr_0=arr)
        pair = RecganPair("chair", "03001627", "train_125", "train", "same", "aa", "0_0_0",
                          paths["input"], paths["target"])
        return pair, str(paths[bad])
    return write


# canonical depth cache: 3 subjects x (canonical + 3 poses), 32^2 discs; one image broken
S = 32


def _disc(size: int = S) -> tuple[np.ndarray, np.ndarray]:
    y, x = np.mgrid[:size, :size] / size - 0.5
    m = x**2 + y**2 < 0.09
    return np.where(m, 0.6, 0.0).astype(np.float16), m


def write_depth_cache(root: Path, breaker: Callable | None, skip_bad: bool = False) -> CanonicalDataModule:
    """A complete canonical cache as ``prepare_data`` leaves it (manifest + one ``subjects/<s>.npz``
    per subject), with ``depth_1_0`` of subject ``s1`` passed through ``breaker(depth, mask)``."""
    subjects, poses = ("s0", "s1", "s2"), ("0", "1", "2")
    dm = CanonicalDataModule.from_flat(str(root), image_size=S, n_subjects=3, n_poses=3, n_folds=2, batch_size=2,
                             skip_bad=skip_bad)
    builder = dm.cache_builder()
    builder.begin()
    builder.path("subjects").mkdir()
    for s in subjects:
        arrays = {"poses": np.array(poses), "skipped": np.array([], dtype=str)}
        for p in ("canonical", *poses):
            d, m = _disc()
            if breaker is not None and (s, p) == ("s1", "1"):
                d, m = breaker(d, m)
            arrays[f"depth_{p}_0"], arrays[f"mask_{p}_0"] = d, np.packbits(m)
        np.savez(builder.path(f"subjects/{s}.npz"), **arrays)
    builder.finish([{"file": f"subjects/{s}.npz", "subject": s} for s in subjects],
                   extra={"complete": True, "subjects": list(subjects), "categories": {}})
    return dm


def _depth(breaker):
    def write(tmp: Path):
        return write_depth_cache(tmp / "cache", breaker), str(tmp / "cache" / "subjects" / "s1.npz")
    return write


def _mos(**kw):
    def write(tmp: Path):
        root = liris_epfl(tmp / "liris", **kw)
        return root, str(root / "MOS_GeneralPurpose.xlsx")
    return write


def _option(text: str, named: str | None = None):
    return lambda tmp: (text, named or text)


class _TouchOnLoad:
    """Pickles as ``open(path, "w")``: unpickling it would create ``path``."""

    def __init__(self, path: Path):
        self.path = str(path)

    def __reduce__(self):
        return (open, (self.path, "w"))


def _ckpt(kind: str):
    def write(tmp: Path):
        p = tmp / f"{kind}.ckpt"
        if kind == "completion":  # a lit3d checkpoint of the completion task (only what eval reads first)
            torch.save({"state_dict": {}, "lit3d": {"task": {"name": "completion"}, "data": {}, "wandb_id": None}}, p)
        elif kind == "pickled":
            torch.save({"state_dict": {}, "lit3d": _TouchOnLoad(tmp / "was_executed")}, p)
        elif kind == "garbage":
            p.write_bytes(GARBAGE)
        elif kind == "foreign":  # a valid torch file without lit3d metadata
            torch.save({"state_dict": {"w": torch.zeros(2)}}, p)
        return p, str(p)
    return write
