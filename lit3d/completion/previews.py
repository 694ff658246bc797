"""Validation previews of the completion task for the run's image loggers (W&B, TensorBoard).

On the first validation batch, for its first sample:
- ``val/panels``: the rendered figure (input | stages | prediction | target,
  :func:`lit3d.completion.figures.split_figure`) every ``image_every_n_epochs`` epochs;
- ``val/mesh/prediction`` and ``val/mesh/target``: marching-cubes surfaces of the prediction (at the
  validation-chosen threshold) and of the target as 3D objects every ``mesh_every_n_epochs`` epochs
  (0: never; not during the sanity check). Both meshes share one frame: voxel centres mapped to
  ``[-0.5, 0.5]^3``. Grids finer than :data:`PREVIEW_RES`^3 are average-pooled to it first, so that a
  mesh stays small (a 256^3 surface would be tens of MB of OBJ text every time).
Nothing is rendered when the run has no such logger (:mod:`lit3d.utils.log_images`).
"""
from __future__ import annotations

import logging

import numpy as np
import torch
import torch.nn.functional as F

from lit3d.completion.figures import split_figure
from lit3d.render.convert import ShapeError, voxels_to_mesh
from lit3d.utils.log_images import log_image, log_mesh, media_loggers

log = logging.getLogger("lit3d.completion")

PREVIEW_RES = 64  # the meshes' grid resolution at most


def log_validation_previews(task, batch: dict) -> None:
    """Panels and meshes of ``batch``'s first sample to ``task``'s image loggers when due (rank 0)."""
    if not task.trainer.is_global_zero:
        return
    loggers = media_loggers(task.loggers)
    if not loggers:
        return
    epoch, step = task.current_epoch, task.global_step
    if epoch % max(int(task.panels.image_every_n_epochs), 1) == 0:
        sample = {"input": batch["input"][0].cpu(), "target": batch["target"][0].cpu(), "category": batch["category"][0]}
        log_image(loggers, "val/panels", split_figure(task, [sample], f"validation, epoch {epoch}"), step)
    every = int(task.panels.mesh_every_n_epochs or 0)
    if every > 0 and epoch % every == 0 and not task.trainer.sanity_checking:
        for name, (verts, faces) in sample_meshes(task, batch["input"][0], batch["target"][0]).items():
            log_mesh(loggers, f"val/mesh/{name}", verts, faces, step)


def sample_meshes(task, partial: torch.Tensor, target: torch.Tensor) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """``{"prediction": (V, 3) float32 vertices + (F, 3) int64 faces, "target": ...}`` of one sample
    (``partial (1, r, r, r)``, ``target (1, R, R, R)``); an empty grid has no surface and is left out."""
    with torch.no_grad():
        probs = task(partial[None].to(task.device))[0, 0].float().cpu()
    probs, target = _preview_grid(probs), _preview_grid(target[0].float().cpu())
    res = probs.shape[-1]
    grids = {"prediction": (probs, float(task.threshold)), "target": (target, 0.5)}
    out = {}
    for name, (grid, level) in grids.items():
        try:
            mesh = voxels_to_mesh(grid, f"validation {name}", level)
        except ShapeError as exc:
            log.info("no %s mesh logged: %s", name, exc)
            continue
        # marching cubes ran on the grid padded by one voxel: vertex i + 1 is voxel centre i
        verts = (np.asarray(mesh.vertices, np.float32) - 1.0 - (res - 1) / 2) / res
        out[name] = (verts, np.asarray(mesh.faces, np.int64))
    return out


def _preview_grid(grid: torch.Tensor) -> np.ndarray:
    """``(R, R, R)`` -> ``(R/f, R/f, R/f)`` float32 array, average-pooled by ``f = R // PREVIEW_RES``."""
    factor = grid.shape[-1] // PREVIEW_RES
    if factor > 1:
        grid = F.avg_pool3d(grid[None, None], factor)[0, 0]
    return grid.numpy()
