"""Contact sheets of the canonical task: one PNG per subject, one row per held-out pose (view).

Columns: ``posed input | predicted canonical | predicted, shaded surface | true canonical |
true, shaded surface | |error|``. Depth tiles are grey (near = bright, background black),
nearest-upsampled to the cell size; the shaded surfaces are the depth images back-projected
(:func:`lit3d.render.depth.depth_to_mesh`) and rendered with a MatCap style
(:func:`lit3d.render.shaded.shaded_views`) from a view turned 25 degrees right and 15 up, so
relief (limbs in front of the body, a flat or bent torso) shows.
"""
from __future__ import annotations

import numpy as np
import torch
from PIL import Image

from lit3d.metrics.depth import composite_depth
from lit3d.render.depth import ORTHO_MAG, depth_to_mesh
from lit3d.render.shaded import shaded_views
from lit3d.utils.figures import labelled_grid

CELL = 256
COLUMNS = ["posed input", "predicted canonical", "predicted, shaded", "true canonical", "true, shaded",
           "|error| (max = white)"]
SURFACE_VIEW = (0.45, 0.27, 0.85)  # GL direction shape -> camera (the depth camera looks down -z)
SURFACE_STYLE = "clay_studio"


def depth_tile(depth: np.ndarray, size: int = CELL) -> np.ndarray:
    """``(size, size, 3) uint8`` grey tile of a ``(S, S)`` depth image in [0, 1] (0 = background)."""
    img = Image.fromarray((np.clip(depth, 0, 1) * 255).astype(np.uint8)).resize((size, size), Image.NEAREST)
    return np.repeat(np.asarray(img)[..., None], 3, axis=2)


def surface_tile(depth: np.ndarray, mask: np.ndarray, size: int = CELL) -> np.ndarray:
    """``(size, size, 3) uint8`` shaded render of a depth image's back-projected surface (white
    when the mask is empty)."""
    verts, faces = depth_to_mesh(depth, mask)
    if len(faces) == 0:
        return np.full((size, size, 3), 255, np.uint8)
    import trimesh

    mesh = trimesh.Trimesh(verts, faces, process=False)
    return shaded_views(mesh, [SURFACE_VIEW], size, SURFACE_STYLE, extent=ORTHO_MAG * 1.05)[0]


def sheet_rows(batch: dict, out, threshold: float, size: int = CELL) -> list[dict]:
    """Labelled rows of one batch: ``batch`` holds ``depth, mask, canon_depth, canon_mask``
    ``(B, 1, S, S)`` and optionally ``pose``/``view``; ``out`` has ``depth``/``mask`` ``(B, 1, S, S)``
    (mask as a probability)."""
    rows = []
    for i in range(batch["depth"].shape[0]):
        pm = (out.mask[i, 0] >= threshold).float().cpu()
        pred = composite_depth(out.depth[i, 0].float().cpu(), pm).numpy()
        tgt, tmask = batch["canon_depth"][i, 0].cpu().numpy(), batch["canon_mask"][i, 0].cpu().numpy()
        err = np.abs(pred - tgt)
        cells = [depth_tile(batch["depth"][i, 0].cpu().numpy(), size), depth_tile(pred, size),
                 surface_tile(pred, pm.numpy(), size), depth_tile(tgt, size), surface_tile(tgt, tmask, size),
                 depth_tile(err / max(float(err.max()), 1e-6), size)]
        label = f"pose {int(batch['pose'][i])}" if "pose" in batch else f"item {i}"
        if "view" in batch:
            label += f"\nview {int(batch['view'][i])}"
        mse = float(((pred - tgt) ** 2)[(pm.numpy() > 0) | (tmask > 0.5)].mean()) if err.any() else 0.0
        rows.append({"label": label + f"\ndepth MSE {mse:.4f}", "cells": cells})
    return rows


def contact_sheet(subject: str, rows: list[dict], size: int = CELL) -> Image.Image:
    """The labelled sheet of one subject."""
    title = (f"Canonical form of '{subject}' from one depth image: prediction vs truth "
             "(shaded = depth back-projected and rendered from 25 deg right, 15 deg up)")
    return labelled_grid(rows, COLUMNS, title, size, left=170)


def subject_sheets(task, dataset, n: int = 4, size: int = CELL) -> dict[str, Image.Image]:
    """``{subject: sheet}`` for up to ``n`` items per subject of ``dataset`` (canonical dataset items)."""
    by_subject: dict[str, list[int]] = {}
    for i, r in enumerate(dataset.records):
        by_subject.setdefault(r["subject"], []).append(i)
    dev = next(task.parameters()).device
    sheets = {}
    for subject, idx in sorted(by_subject.items()):
        items = [dataset[i] for i in idx[:n]]
        batch = {k: torch.stack([it[k] for it in items]).to(dev) for k in ("depth", "mask", "canon_depth", "canon_mask")}
        batch["pose"] = torch.tensor([it["pose"] for it in items])
        batch["view"] = torch.tensor([it["view"] for it in items])
        with torch.no_grad():
            out = task(batch["depth"], batch["mask"])
        sheets[subject] = contact_sheet(subject, sheet_rows(batch, out, task.hparams.mask_threshold, size), size)
    return sheets


def validation_panel(batch: dict, out, n: int, threshold: float) -> np.ndarray:
    """uint8 image ``(n * (S + 2), 4 * (S + 2))`` of the first ``n`` samples of a batch, one row each:
    input | predicted | target depth | |error| (each tile padded by 1 px); ``out`` the net's
    :class:`~lit3d.canonical.outputs.CanonicalOutput`, its mask binarised at ``threshold``."""
    n = min(n, batch["depth"].shape[0])
    rows = []
    for i in range(n):
        pred = composite_depth(out.depth[i, 0], out.mask[i, 0], threshold).detach().float().cpu()
        tgt = batch["canon_depth"][i, 0].cpu()
        tiles = [batch["depth"][i, 0].cpu(), pred, tgt, (pred - tgt).abs()]
        rows.append(torch.cat([torch.nn.functional.pad(t, (1, 1, 1, 1), value=0.3) for t in tiles], 1))
    return (torch.cat(rows, 0).clamp(0, 1).numpy() * 255).astype(np.uint8)
