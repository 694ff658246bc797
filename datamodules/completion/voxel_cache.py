"""Packed-bit voxel pairs on disk and the Dataset that reads them.

One item = one ``.npz`` with two arrays: ``bits`` = ``np.packbits(input)`` followed
by ``np.packbits(target)`` (each padded to whole bytes) and ``shapes`` = int64
``(2, 3)``, the input and target grid shapes. Bits are 1/8 of int8 and unpack at
memory speed; ``float32`` exists only in memory. (Two keys, not four: every npz key
costs about 0.6 ms of zip parsing, more than unpacking a 64^3 grid.)
"""
from __future__ import annotations

import os
import time
import zipfile
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch
from torch.utils.data import Dataset

from datamodules.cache import DataError, atomic_save_npz, check_unchanged
from lit3d.utils.shapenet_categories import SEEN_CATEGORIES

# the completion cache's splits (items/<split>/ and the manifest's "split"); the test ones in test order
DATA_SPLITS = ("train", "val", "test_same", "test_cross", "test_unseen", "test_unseen_cross")
TEST_SPLITS = DATA_SPLITS[2:]


def save_pair(path: str | os.PathLike, input: np.ndarray, target: np.ndarray, compress: bool = True) -> Path:
    """Write one (input, target) pair of 3D boolean grids as packed bits, atomically."""
    inp, tgt = np.asarray(input, dtype=bool), np.asarray(target, dtype=bool)
    if inp.ndim != 3 or tgt.ndim != 3:
        raise ValueError(f"expected 3D grids, got {inp.shape} and {tgt.shape}")
    bits = np.concatenate([np.packbits(inp, axis=None), np.packbits(tgt, axis=None)])
    return atomic_save_npz(path, compress=compress, bits=bits, shapes=np.asarray([inp.shape, tgt.shape], np.int64))


def load_pair(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """(input, target) uint8 {0,1} grids of one cached item.

    Raises:
        DataError: naming the file when it is unreadable, lacks a key or is truncated.
    """
    try:
        with np.load(path) as z:
            bits, shapes = z["bits"], z["shapes"]
        n_in, n_tg = int(np.prod(shapes[0])), int(np.prod(shapes[1]))
        split = (n_in + 7) // 8
        if bits.size != split + (n_tg + 7) // 8:
            raise ValueError(f"{bits.size} bytes of bits do not match shapes {shapes.tolist()}")
        inp = np.unpackbits(bits[:split], count=n_in).reshape(shapes[0])
        tgt = np.unpackbits(bits[split:], count=n_tg).reshape(shapes[1])
        return inp, tgt
    except (OSError, KeyError, ValueError, zipfile.BadZipFile) as exc:
        check_unchanged(items=False)  # another process re-preparing the folder: say that instead
        raise DataError(f"{path}: unreadable cached voxel pair ({type(exc).__name__}: {exc}); "
                        "delete the file and run prepare_data() again") from exc


def max_pool_bool(grid: np.ndarray, factor: int) -> np.ndarray:
    """(R, R, R) bool -> (R/f,)*3 bool: a voxel is set when any of its f^3 children is.

    Factors 2, 4, 8 pool the contiguous last axis by viewing f bools as one
    uint16/32/64 (about 30x faster than ``reshape(...).any(axis=(1, 3, 5))`` at 256^3);
    other factors are split into such stages where possible.
    """
    if factor == 1:
        return np.asarray(grid, dtype=bool)
    if grid.ndim != 3 or any(n % factor for n in grid.shape):
        raise ValueError(f"grid {grid.shape} cannot be max-pooled by {factor}")
    for f in (8, 4, 2):
        if factor > f and factor % f == 0:
            return max_pool_bool(max_pool_bool(grid, f), factor // f)
    a, b, c = (n // factor for n in grid.shape)
    g = np.ascontiguousarray(grid, dtype=bool)
    dt = {2: np.uint16, 4: np.uint32, 8: np.uint64}.get(factor)
    if dt is None:
        return g.reshape(a, factor, b, factor, c, factor).any(axis=(1, 3, 5))
    x = g.view(np.uint8).view(dt) != 0  # (A, B, c): last axis pooled
    x = np.logical_or.reduce(x.reshape(a, factor, b * factor * c), axis=1)
    return np.logical_or.reduce(x.reshape(a, b, factor, c), axis=2)


def category_label(category: str, seen: Sequence[str] = SEEN_CATEGORIES) -> int:
    """Index of ``category`` in ``seen`` or -1 (unseen)."""
    return seen.index(category) if category in seen else -1


def pair_sample(inp: np.ndarray, tgt: np.ndarray, item: dict, seen: Sequence[str]) -> dict:
    """One dataset sample from an (r, r, r) input and (R, R, R) target occupancy grid.

    Returns ``input`` (1, r, r, r) float32, ``target`` (1, R, R, R) float32, ``label`` int64
    (index into ``seen`` or -1) and the item's ``category``, ``split`` and ``name``.
    """
    return {
        # numpy cast: torch's multi-threaded cast costs ~20 ms per 64^3 grid on a busy 2-core box
        "input": torch.from_numpy(inp.astype(np.float32)[None]),
        "target": torch.from_numpy(tgt.astype(np.float32)[None]),
        "label": torch.tensor(category_label(item["category"], seen), dtype=torch.int64),
        "category": item["category"],
        "split": item["split"],
        "name": item["name"],
    }


class VoxelPairDataset(Dataset):
    """Items of a packed voxel cache.

    Each sample is a dict:
        input    (1, r, r, r) float32 {0,1}  partial 2.5D grid
        target   (1, R, R, R) float32 {0,1}  complete solid
        label    int64 index into ``seen`` (bench, chair, couch, table) or -1
        category str, split str, name str
    """

    def __init__(self, root: str | os.PathLike, items: Sequence[dict], seen: Sequence[str] = SEEN_CATEGORIES):
        self.root = Path(root)
        self.items = list(items)
        self.seen = tuple(seen)

    def __len__(self) -> int:
        return len(self.items)

    def __getitem__(self, idx: int) -> dict:
        it = self.items[idx]
        return pair_sample(*load_pair(self.root / it["file"]), it, self.seen)


class Int8NpzPairDataset(Dataset):
    """The same samples as :class:`VoxelPairDataset` read from raw int8 ``.npz`` files
    (keys ``input``, ``target``): the format packed bits replace, kept as the loading baseline."""

    def __init__(self, paths: Sequence[str | os.PathLike], items: Sequence[dict], seen: Sequence[str] = SEEN_CATEGORIES):
        self.paths = [Path(p) for p in paths]
        self.items = list(items)
        self.seen = tuple(seen)

    def __len__(self) -> int:
        return len(self.paths)

    def __getitem__(self, idx: int) -> dict:
        it = self.items[idx]
        with np.load(self.paths[idx]) as z:
            inp, tgt = z["input"], z["target"]
        return pair_sample(inp, tgt, it, self.seen)


def write_int8_copies(root: str | os.PathLike, items: Sequence[dict], tmp_dir: str | os.PathLike,
                      compress: bool = False) -> list[Path]:
    """Write each cached pair of ``items`` as a raw int8 ``.npz`` into ``tmp_dir``; returns the paths."""
    tmp_dir = Path(tmp_dir)
    tmp_dir.mkdir(parents=True, exist_ok=True)
    fn = np.savez_compressed if compress else np.savez
    paths = []
    for i, it in enumerate(items):
        inp, tgt = load_pair(Path(root) / it["file"])
        p = tmp_dir / f"int8{'_z' if compress else ''}_{i}.npz"
        fn(p, input=inp.astype(np.int8), target=tgt.astype(np.int8))
        paths.append(p)
    return paths


def measure_loading(root: str | os.PathLike, items: Sequence[dict], tmp_dir: str | os.PathLike,
                    n: int = 64, batch_size: int = 1, num_workers: int = 0, passes: int = 3) -> dict[str, float]:
    """Samples/s of a ``DataLoader`` over the packed-bit cache vs the same pairs as raw int8 ``.npz``.

    Both go through ``torch.utils.data.DataLoader`` with ``batch_size`` and ``num_workers``
    (the training configuration) and the default collate. Up to ``n`` items; int8 copies
    (uncompressed and zlib-compressed) are written into ``tmp_dir``. Each variant is read
    once to warm the page cache, then the median of ``passes`` full passes is taken.

    Returns:
        ``{variant: samples/s}`` for ``packed_bits``, ``int8_npz``, ``int8_npz_compressed``,
        and ``bytes_per_item/<variant>``.
    """
    import statistics

    from torch.utils.data import DataLoader

    items = list(items)[:n]
    raw = {"int8_npz": write_int8_copies(root, items, tmp_dir, compress=False),
           "int8_npz_compressed": write_int8_copies(root, items, tmp_dir, compress=True)}
    datasets = {"packed_bits": VoxelPairDataset(root, items)}
    datasets.update({k: Int8NpzPairDataset(v, items) for k, v in raw.items()})

    def one_pass(ds) -> float:
        loader = DataLoader(ds, batch_size=batch_size, shuffle=False, num_workers=num_workers)
        t0 = time.perf_counter()
        count = sum(int(b["input"].shape[0]) for b in loader)
        return count / max(time.perf_counter() - t0, 1e-9)

    out = {}
    for key, ds in datasets.items():
        one_pass(ds)  # warm the page cache (and the worker start-up path)
        out[key] = statistics.median(one_pass(ds) for _ in range(max(passes, 1)))
    sizes = {"packed_bits": sum((Path(root) / it["file"]).stat().st_size for it in items)}
    sizes.update({k: sum(p.stat().st_size for p in v) for k, v in raw.items()})
    out.update({f"bytes_per_item/{k}": v / max(len(items), 1) for k, v in sizes.items()})
    return out
