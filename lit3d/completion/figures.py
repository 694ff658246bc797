"""Completion figures a person can read: shaded 3D renders of the voxel grids, labelled.

One PNG per test split (``completion_<split>.png``): per sample two rows (front view, from the
depth camera's side, and back view), columns ``input | stage 1 | stage 2 | prediction | target``
(the stages of the cascade before the last one; ``prediction`` is the final stage at the
validation-chosen threshold). Coarse grids (the r^3 input and intermediate stages) are
nearest-upsampled to R^3 so they show as voxels at the same scale as the shapes. Each cell is a
marching-cubes surface rendered with the project's G-buffer pass and a MatCap style
(:func:`lit3d.render.voxel_images.render_voxels`).
"""
from __future__ import annotations

from collections import defaultdict

import torch

from lit3d.metrics.voxel import iou_at_thresholds
from lit3d.utils.figures import labelled_grid
from lit3d.render.voxel_images import BACK_VIEW, FRONT_VIEW, render_voxels, to_resolution

CELL = 256          # px per rendered cell (each view)
HEADER, LEFT = 44, 210
INPUT_STYLE, SHAPE_STYLE, TARGET_STYLE = "matt_blue", "clay_studio", "clay_brown"


def sample_columns(task, partial: torch.Tensor, target: torch.Tensor) -> tuple[list[str], list[torch.Tensor], list[str]]:
    """Names, grids (each ``(R, R, R)`` float32 in [0, 1]) and styles of one sample's columns.

    Args:
        task: a ``CompletionTask`` (its generator and ``threshold`` are used).
        partial: ``(1, r, r, r)`` float32 {0, 1}; target: ``(1, R, R, R)`` float32 {0, 1}.
    """
    with torch.no_grad():
        out = task.generator(partial[None].to(task.device))
    res = int(target.shape[-1])
    names, vols, styles = ["input"], [to_resolution(partial[0].float(), res)], [INPUT_STYLE]
    for i, lg in enumerate(out.stage_logits[:-1]):
        names.append(f"stage {i + 1}")
        vols.append(to_resolution(torch.sigmoid(lg[0, 0].float()).cpu(), res))
        styles.append(SHAPE_STYLE)
    names += ["prediction", "target"]
    vols += [torch.sigmoid(out.logits[0, 0].float()).cpu(), target[0].float()]
    styles += [SHAPE_STYLE, TARGET_STYLE]
    return names, vols, styles


def figure(rows: list[dict], columns: list[str], title: str, cell: int = CELL):
    """Labelled cells (:func:`lit3d.utils.figures.labelled_grid` with this figure's margins)."""
    return labelled_grid(rows, columns, title, cell, LEFT, HEADER)


def collect_samples(loader, per_category: int) -> list[dict]:
    """Up to ``per_category`` samples of every category of a test loader, in loader order:
    ``[{"input": (1, r, r, r), "target": (1, R, R, R), "category": str}]``."""
    got: dict[str, int] = defaultdict(int)
    out = []
    for batch in loader:
        for i, cat in enumerate(batch["category"]):
            if got[cat] < per_category:
                got[cat] += 1
                out.append({"input": batch["input"][i], "target": batch["target"][i], "category": cat})
    return sorted(out, key=lambda s: s["category"])


def _iou(probs: torch.Tensor, target: torch.Tensor, threshold: float) -> float:
    """IoU of ``(R, R, R)`` probabilities at ``threshold`` against a ``(1, R, R, R)`` {0, 1} target."""
    return float(iou_at_thresholds(probs[None, None], target[None], torch.tensor([threshold]))[0, 0])


def split_figure(task, samples: list[dict], split: str, cell: int = CELL):
    """The figure of one split (``split`` names it in the title, e.g. "same-view test split"):
    two rows (front, back view) per sample."""
    threshold = float(task.threshold)
    rows, columns = [], []
    for s in samples:
        columns, vols, styles = sample_columns(task, s["input"], s["target"])
        pred_iou = _iou(vols[-2], s["target"], threshold)
        inp_iou = _iou(vols[0], s["target"], 0.5)
        views = [render_voxels(v, threshold if c else 0.5, cell, (FRONT_VIEW, BACK_VIEW), style)
                 for c, (v, style) in enumerate(zip(vols, styles))]
        for k, side in enumerate(("front", "back")):
            label = f"{s['category']}\n{side} view"
            if k == 0:
                label += f"\nIoU {pred_iou:.2f}\ninput as\nprediction {inp_iou:.2f}"
            rows.append({"label": label, "cells": [v[k] for v in views]})
    title = (f"Shape completion, {split}: shaded marching-cubes renders "
             f"(threshold {threshold:.2f}; input and stages nearest-upsampled to {samples[0]['target'].shape[-1]}^3)")
    return figure(rows, columns, title, cell)
