"""Cached canonical-form depth images: the checks every image passes and the reader of one
subject's cache file.

A subject's file (``subjects/<subject>.npz``) holds, for the canonical pose and every kept pose
``p`` and view ``v``: ``depth_<p>_<v>`` ``(S, S)`` float16 in [0, 1] (0 = background) and
``mask_<p>_<v>`` (``np.packbits`` of the ``(S, S)`` bool mask); ``poses`` (str) lists the kept
poses and ``skipped`` (str) the problems of poses dropped while rendering (``skip_bad``).
"""
from __future__ import annotations

import io
import zipfile
from pathlib import Path

import numpy as np

from datamodules.cache import DataError, read_manifest
from lit3d.utils.figures import labelled_grid
from lit3d.utils.io import atomic_write_bytes


def depth_image_problem(depth: np.ndarray, mask: np.ndarray | None, size: int) -> str | None:
    """What is wrong with one depth image ``(S, S)`` and its mask ``(S, S)``, or None.

    Checked: both ``size`` x ``size``, depth finite, something in view (mask and depth not all
    background)."""
    if depth.shape != (size, size):
        return f"depth image has shape {tuple(depth.shape)}, expected ({size}, {size}) (data.image_size={size})"
    if mask is None or mask.shape != (size, size):
        return f"mask missing or not {size} x {size}"
    if not np.isfinite(depth).all():
        return "depth image contains NaN or inf"
    if not mask.any() or not (depth > 0).any():
        return "depth image is all background (nothing in view)"
    return None


def unpack_mask(packed: np.ndarray | None, size: int) -> np.ndarray | None:
    """``np.packbits`` of an ``(S, S)`` bool mask -> ``(S, S)`` bool; None when absent or of another size."""
    if packed is None or packed.size != (size * size + 7) // 8:
        return None
    return np.unpackbits(packed)[: size * size].reshape(size, size).astype(bool)


def read_subject(path: Path, size: int, n_views: int) -> tuple[dict | None, list[str]]:
    """One subject's cache file -> (``{"depth", "mask", "flow", "vis", "poses"}`` of its valid images,
    problems). ``flow`` ``{"<p>_<v>": (2, S, S) float16}`` and ``vis`` (``(S, S)`` float32) hold the flow
    targets present (none without them); a flow of the wrong shape or not finite, or one without its
    visibility, is a problem.

    A pose with a bad or missing view is left out of ``poses``; a bad canonical view gives
    ``None`` (the subject cannot be used). Each problem names the file and the image.

    Raises:
        DataError: the file is missing or not a readable ``.npz``.
    """
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise DataError(f"{path}: unreadable cached subject ({type(exc).__name__}: {exc}); "
                        "delete it and run lit3d-data again") from exc
    depth, mask, problems = {}, {}, []
    listed = ["canonical"] + [str(p) for p in arrays.get("poses", [])]
    for key in (f"{p}_{v}" for p in listed for v in range(n_views)):
        if f"depth_{key}" not in arrays:
            problems.append(f"{path}: depth_{key}: depth image missing")
            continue
        d = arrays[f"depth_{key}"].astype(np.float32)
        m = unpack_mask(arrays.get(f"mask_{key}"), size)
        problem = depth_image_problem(d, m, size)
        if problem:
            problems.append(f"{path}: depth_{key}: {problem}")
        else:
            depth[key], mask[key] = d, m.astype(np.float32)
    complete = [p for p in listed if all(f"{p}_{v}" in depth for v in range(n_views))]
    if "canonical" not in complete:
        return None, problems
    flow, vis = {}, {}
    for key in (f"{p}_{v}" for p in complete[1:] for v in range(n_views)):
        if f"flow_{key}" not in arrays:
            continue
        f, m = arrays[f"flow_{key}"], unpack_mask(arrays.get(f"vis_{key}"), size)
        if f.shape != (2, size, size) or m is None or not np.isfinite(f).all():
            problems.append(f"{path}: flow_{key}: flow target not (2, {size}, {size}) and finite, or its "
                            "visibility missing")
            continue
        flow[key], vis[key] = f, m.astype(np.float32)
    return {"depth": depth, "mask": mask, "flow": flow, "vis": vis, "poses": [int(p) for p in complete[1:]]}, problems


def depth_pairs_png(dataset, n: int, path: str | Path, cell: int = 256) -> Path:
    """Labelled PNG (written atomically) of ``n`` items spread over ``dataset`` (a
    :class:`~datamodules.canonical.dataset.CanonicalPairDataset`), one row each (subject, pose): posed depth |
    posed mask | canonical depth | canonical mask, each ``(S, S)`` image enlarged (nearest) to at least ``cell`` px."""
    rows, size = [], 0
    for i in np.linspace(0, len(dataset) - 1, min(n, len(dataset))).astype(int):
        b = dataset[int(i)]
        size = b["depth"].shape[-1]
        scale = -(-cell // size)  # the smallest whole factor that reaches cell px
        tiles = [np.kron((b[k][0].numpy() * 255).clip(0, 255).astype(np.uint8), np.ones((scale, scale), np.uint8))
                 for k in ("depth", "mask", "canon_depth", "canon_mask")]
        rows.append({"label": f"{b['subject']}\npose {int(b['pose'])}", "cells": [np.stack([t] * 3, -1) for t in tiles]})
    img = labelled_grid(rows, ["posed depth", "posed mask", "canonical depth", "canonical mask"],
                        f"canonical-form pairs: {len(rows)} of {len(dataset)} items, {size}x{size} px images enlarged",
                        cell=rows[0]["cells"][0].shape[0], left=170)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    buf = io.BytesIO()
    img.save(buf, format="PNG")
    atomic_write_bytes(path, buf.getvalue())
    return path


def remove_legacy_subject_files(data_dir: str | Path) -> None:
    """Delete the subject files of the cache layout before CacheBuilder (``data_dir/<subject>.npz``,
    listed by a manifest without ``generator``); the new layout renders them again."""
    data_dir = Path(data_dir)
    try:
        man = read_manifest(data_dir)
    except DataError:
        return
    if man is not None and "generator" not in man:
        for s in man.get("subjects", []):
            (data_dir / f"{s}.npz").unlink(missing_ok=True)
