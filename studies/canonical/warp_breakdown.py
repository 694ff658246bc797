"""Where the warp head's mask IoU goes: the output composed again with the net's flow, visibility and
fill each replaced by the truth, on the items of a split.

    python -m studies.canonical.warp_breakdown CKPT [--split val|test] [--data-dir DIR] [--out FILE.md]
                                             [--picture FILE.png]

The data are the checkpoint's own (its data config; ``--data-dir`` reads a cache elsewhere), with flow
targets (``data.render.flow_targets=true``). Per item and row, the mask IoU (at 0.5) against the true
canonical mask; the table gives the means. The "true fill" is the target itself (depth and mask), the
"true visibility" the cached one (0 on the canonical background, so there the fill is taken). Also:
the model's missed and extra pixels (a share of the true area), and the flow's end-point error in
pixels where the posed view shows the point and where it hides it.

Measured this way on the demo (docs/results_canonical.md): the flow is right on the canonical body, but
the background beside a posed limb reads that limb where it was posed, and the visibility, unpaid there,
stays near 1: the limb stays in the output.
"""
from __future__ import annotations

import argparse
import sys
from collections.abc import Iterable
from pathlib import Path

import numpy as np
import torch

from datamodules.canonical import CanonicalDataModule
from lit3d.canonical.checkpoint_upgrade import upgrade_checkpoint
from lit3d.canonical.module import CanonicalTask
from lit3d.canonical.warp import WarpHead, pixels_to_grid, warp_compose, warp_image
from lit3d.metrics.depth import per_sample_mask_iou
from lit3d.utils.checkpoints import META_KEY, load_checkpoint
from lit3d.utils.figures import labelled_grid
from lit3d.utils.io import atomic_file, atomic_write_text, check_targets, output_error

PICTURE_ITEMS = 4  # rows of --picture: the split's first items
PICTURE_COLUMNS = ["posed mask", "true canonical", "output vs truth", "moved by the flow", "visibility"]

# (row, flow, visibility, fill): "pred" the net's, "true" the target's, "true on the body" the true flow on the
# canonical foreground and the net's elsewhere
ROWS = (
    ("the model", "pred", "pred", "pred"),
    ("true fill", "pred", "pred", "true"),
    ("true visibility", "pred", "true", "pred"),
    ("true visibility and fill", "pred", "true", "true"),
    ("true flow on the body", "true on the body", "pred", "pred"),
    ("true flow on the body, true fill", "true on the body", "pred", "true"),
    ("true flow, visibility and fill (the oracle)", "true", "true", "true"),
)


@torch.no_grad()
def predict(net, batch: dict) -> dict[str, torch.Tensor]:
    """The warp head's pieces for one batch (:meth:`~lit3d.canonical.warp.WarpHead.parts`: ``flow``,
    ``coeffs``, ``vis_logits``, ``fill_depth``, ``fill_mask``), with ``vis`` (the visibility probability)
    and ``mask`` (the output's mask probability, ``(B, 1, H, W)``). ValueError without a warp head."""
    if not isinstance(getattr(net, "head", None), WarpHead):
        raise ValueError("the breakdown needs a warp head (task.net.head.kind=warp)")
    p = net.head.parts(*net.features(batch["depth"], batch["mask"]))
    p["vis"] = torch.sigmoid(p["vis_logits"])
    p["mask"] = warp_compose(batch["depth"], batch["mask"], p["flow"], p["coeffs"], p["vis"], p["fill_depth"],
                             p["fill_mask"])[1]
    return p


@torch.no_grad()
def breakdown(net, batch: dict, pred: dict | None = None) -> dict[str, torch.Tensor]:
    """Per-item figures ``(B,)`` of one batch (``depth``, ``mask``, ``canon_depth``, ``canon_mask``, ``flow``
    in pixels, ``vis``: ``datamodules.canonical`` with flow targets): a mask IoU per :data:`ROWS` row,
    the posed input's, the model's ``missed`` / ``extra`` pixels per true pixel, and the flow error in
    pixels on the ``visible`` / ``hidden`` canonical body (NaN where an item has none). ``pred``: the
    batch's :func:`predict`, when the caller has it."""
    p = predict(net, batch) if pred is None else pred
    depth, mask, target = batch["depth"], batch["mask"], batch["canon_mask"].float()
    true_flow, true_vis = pixels_to_grid(batch["flow"].float()), batch["vis"].float()
    body = target > 0.5
    flows = {"pred": p["flow"], "true": true_flow, "true on the body": torch.where(body, true_flow, p["flow"])}
    vis = {"pred": p["vis"], "true": true_vis}
    fills = {"pred": (p["fill_depth"], p["fill_mask"]), "true": (batch["canon_depth"].float(), target)}
    out = {ROWS[0][0]: per_sample_mask_iou(p["mask"], target)}  # the model: the output itself
    for name, f, v, fill in ROWS[1:]:
        _, m = warp_compose(depth, mask, flows[f], p["coeffs"], vis[v], *fills[fill])
        out[name] = per_sample_mask_iou(m, target)
    out["posed input"] = per_sample_mask_iou(mask, target)
    model = p["mask"]
    area = body.sum((1, 2, 3)).clamp_min(1).float()
    out["missed"] = (body & (model < 0.5)).sum((1, 2, 3)) / area
    out["extra"] = (~body & (model >= 0.5)).sum((1, 2, 3)) / area
    error = ((p["flow"] - true_flow) * depth.shape[-1] / 2).norm(dim=1, keepdim=True)
    for name, where in (("flow error, visible (px)", body & (true_vis > 0.5)),
                        ("flow error, hidden (px)", body & (true_vis <= 0.5))):
        n = where.sum((1, 2, 3)).float()
        out[name] = torch.where(n > 0, (error * where).sum((1, 2, 3)) / n.clamp_min(1), torch.full_like(n, float("nan")))
    return out


def _tile(image: np.ndarray, cell: int) -> np.ndarray:
    """``(H, W)`` in [0, 1] or ``(H, W, 3)`` -> ``(cell, cell, 3)`` uint8, nearest-neighbour enlarged."""
    rgb = np.repeat(image[..., None], 3, -1) if image.ndim == 2 else image
    reps = max(cell // rgb.shape[0], 1)
    big = np.kron(np.clip(rgb, 0, 1), np.ones((reps, reps, 1)))
    out = np.ones((cell, cell, 3))
    out[: big.shape[0], : big.shape[1]] = big[:cell, :cell]
    return (out * 255).astype(np.uint8)


@torch.no_grad()
def picture(net, batch: dict, title: str, n: int = PICTURE_ITEMS, cell: int = 256, pred: dict | None = None):
    """A labelled grid (PIL image) of the first ``n`` items: posed and true canonical masks, the output's
    mask coloured by agreement (green kept, red extra, blue missed), the posed mask moved by the net's flow
    alone, and the visibility (white: the moved pixel is taken). ``pred``: the batch's :func:`predict`."""
    p = predict(net, batch) if pred is None else pred
    vis, model = p["vis"], p["mask"]
    moved = warp_image(batch["mask"], p["flow"])
    iou = per_sample_mask_iou(model, batch["canon_mask"])
    rows = []
    for i in range(min(n, len(model))):
        t, m = batch["canon_mask"][i, 0].numpy() > 0.5, model[i, 0].numpy() >= 0.5
        agree = np.stack([m & ~t, m & t, ~m & t], -1).astype(np.float32)
        cells = [batch["mask"][i, 0].numpy(), t.astype(np.float32), agree, moved[i, 0].numpy(), vis[i, 0].numpy()]
        rows.append({"label": f"item {i}\nIoU {float(iou[i]):.2f}", "cells": [_tile(c, cell) for c in cells]})
    return labelled_grid(rows, PICTURE_COLUMNS, title, cell=cell, left=130)


def summarise(batches: Iterable[dict[str, torch.Tensor]]) -> dict[str, float]:
    """Means over items of :func:`breakdown`'s figures (NaN items left out)."""
    pooled: dict[str, list] = {}
    for figures in batches:
        for k, v in figures.items():
            pooled.setdefault(k, []).append(v.cpu().numpy())
    return {k: float(np.nanmean(np.concatenate(v))) for k, v in pooled.items()}


def markdown(means: dict[str, float], n_items: int, source: str) -> str:
    """The table of :func:`summarise`'s means, ``source`` named above it."""
    lines = [f"Mask IoU breakdown of {source} ({n_items} items)", "", "| row | mean |", "|---|---|"]
    lines += [f"| {k} | {v:.3f} |" for k, v in means.items()]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    """The command line (module docstring). A bad checkpoint, data cache or output path: one line on
    stderr, exit 2; ``--out`` / ``--picture`` never replace the checkpoint and are written atomically."""
    ap = argparse.ArgumentParser(prog="python -m studies.canonical.warp_breakdown", description=__doc__.split("\n\n")[0])
    ap.add_argument("ckpt", help="a canonical checkpoint with the warp head")
    ap.add_argument("--split", choices=("val", "test"), default="test")
    ap.add_argument("--data-dir", help="the data cache (default: the checkpoint's data.data_dir)")
    ap.add_argument("--out", help="also write the table to this markdown file")
    ap.add_argument("--picture", help="also draw the first items (masks, agreement, moved mask, visibility) to this PNG")
    args = ap.parse_args(argv)
    try:
        check_targets([p for p in (args.out, args.picture) if p], protected=[args.ckpt])
        ckpt = upgrade_checkpoint(load_checkpoint(args.ckpt, ValueError), str(args.ckpt))
        data = dict(ckpt.get(META_KEY, {}).get("data") or {})
        data.pop("_target_", None)
        if not (data.get("render") or {}).get("flow_targets"):
            raise ValueError(f"{args.ckpt}: its data have no flow targets (data.render.flow_targets=true is needed)")
        if args.data_dir:
            data["data_dir"] = args.data_dir
        task = CanonicalTask(**ckpt["hyper_parameters"])
        task.load_state_dict(ckpt["state_dict"])
        task.eval()
        dm = CanonicalDataModule(**data)
        dm.prepare_data()
        dm.setup("fit" if args.split == "val" else "test")
        figures, image = [], None
        for batch in dm.val_dataloader() if args.split == "val" else dm.test_dataloader():
            pred = predict(task.net, batch)
            figures.append(breakdown(task.net, batch, pred))
            if args.picture and image is None:  # the split's first items
                run = Path(args.ckpt).resolve().parent.parent.name  # RUN/checkpoints/NAME.ckpt
                title = f"{run}, {args.split} split; output vs truth: green kept, red extra, blue missed"
                image = picture(task.net, batch, title, pred=pred)
        n = sum(len(f["the model"]) for f in figures)
        text = markdown(summarise(figures), n, f"{args.ckpt}, {args.split} split")
        print(text)
        for path, write in ((args.out, lambda p: atomic_write_text(p, text)), (args.picture, lambda p: _save_png(image, p))):
            if path:
                try:
                    write(path)
                except OSError as exc:
                    raise output_error(path, exc) from None
    except ValueError as exc:  # OutputError and DataError are ValueErrors too
        print(f"error: {exc}", file=sys.stderr)
        return 2
    return 0


def _save_png(image, path: str) -> None:
    """``image`` (PIL) to ``path`` as PNG, atomically (:func:`lit3d.utils.io.atomic_file`)."""
    with atomic_file(path) as f:
        image.save(f, format="PNG")


if __name__ == "__main__":
    raise SystemExit(main())
