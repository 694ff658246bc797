"""results.md (in the layout of thesis tables 3.1-3.6) and the PNG figures of shape completion.

Thesis rows are the thesis's published figures on the full 3D-RecGAN++ ShapeNet
data; ours are measured on whatever data the evaluation ran on.
"""
from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import torch

from lit3d.completion.figures import collect_samples, split_figure
from lit3d.completion.module import split_key
from lit3d.completion.surface_report import surface_section
from lit3d.utils.io import atomic_write_bytes, atomic_write_text
from lit3d.utils.log_images import log_image
from lit3d.utils.shapenet_categories import SEEN_CATEGORIES, UNSEEN_CATEGORIES
from lit3d.utils.tables import fmt, markdown_table

# (title, split, categories, {thesis method: [IoU per category]}) from SPEC.md / the thesis.
# lit3d trains one multi-category model, so its row sits beside both the thesis's
# single-category (3.1, 3.3) and multi-category (3.2, 3.4) rows of the same view set.
THESIS = [
    ("Tables 3.1 / 3.2: IoU, same view", "same", SEEN_CATEGORIES, {
        "3D-RecGAN++, single-category (thesis 3.1)": [.580, .647, .753, .679],
        "3DCascade-GAN, single-category (thesis 3.1)": [.641, .701, .809, .698],
        "3DCascade-GAN, multi-category (thesis 3.2)": [.624, .669, .773, .682]}),
    ("Tables 3.3 / 3.4: IoU, cross view", "cross", SEEN_CATEGORIES, {
        "3DCascade-GAN, single-category (thesis 3.3)": [.585, .628, .680, .647],
        "3DCascade-GAN, multi-category (thesis 3.4)": [.574, .620, .673, .633]}),
    ("Table 3.5: IoU, unseen categories, cross view (multi-category training)", "unseen_cross", UNSEEN_CATEGORIES, {
        "3DCascade-GAN, cross view (thesis 3.5)": [.564, .537, .425, .455, .560, .394]}),
    ("Table 3.6: IoU, unseen categories, same view (multi-category training)", "unseen", UNSEEN_CATEGORIES, {
        "3DCascade-GAN, same view (thesis 3.6)": [.559, .541, .430, .455, .569, .395]}),
]
OURS = (("lit3d, multi-category (ours)", ""), ("input as prediction (ours)", "_input"),
        ("silhouette extrusion (ours)", "_extrusion"), ("per-voxel prior (ours)", "_prior"))
SPLIT_TITLES = {"same": "same view", "cross": "cross view", "unseen": "unseen categories, same view",
                "unseen_cross": "unseen categories, cross view"}


def category_rows(metrics: dict, split: str, categories, kind: str = "iou", methods=OURS) -> list[list[str]]:
    """Our rows (``methods``: ``(label, key suffix)``, default the model and baselines) for one split:
    per category + mean."""
    rows = []
    for label, suffix in methods:
        vals = [metrics.get(f"test/{split}/{kind}{suffix}/{c}") for c in categories]
        total = metrics.get(f"test/{split}/{kind}{suffix}")
        if all(v is None for v in vals) and total is None:
            continue
        rows.append([label] + [fmt(v) for v in vals] + [fmt(total)])
    return rows


def write_results(metrics: dict, out_dir: Path, methods=OURS, intro: str | None = None) -> Path:
    """Write results.md: one table per thesis table, thesis rows beside ours, then the surface
    metrics per split. ``methods``: our rows as ``(label, key suffix)`` (default the model and its
    baselines); ``intro``: replaces the threshold line (e.g. for another method's predictions)."""
    val_iou = metrics.get("val/iou")
    threshold_line = (f"Threshold chosen on validation: {fmt(metrics.get('test/threshold'), 2)} "
                      + (f"(validation IoU {fmt(val_iou)})." if val_iou is not None
                         else "(no validation IoU was measured for these weights: no validation batch ran)."))
    parts = [
        "# Shape completion results",
        "",
        f"{intro or threshold_line} IoU per category, last column = mean over test samples.",
        "Rows marked *(thesis)* are the thesis's published figures on the full 3D-RecGAN++ ShapeNet data; "
        "rows marked *(ours)* are measured in this run on this run's data. Compare them only when the data is the same.",
    ]
    for title, split, cats, thesis in THESIS:
        ours = category_rows(metrics, split, cats, methods=methods)
        if not ours:
            continue
        rows = [[name] + [fmt(v) for v in vals] + ["–"] for name, vals in thesis.items()] + ours
        parts += ["", f"## {title}", "", markdown_table(["method", *cats, "mean"], rows)]
        pooled = category_rows(metrics, split, cats, kind="iou_pooled", methods=methods)
        if pooled:
            parts += ["", "Pooled IoU (summed intersections / summed unions; the rows above are per-sample means):",
                      "", markdown_table(["method", *cats, "all"], pooled)]
    for split, cats in (("same", SEEN_CATEGORIES), ("cross", SEEN_CATEGORIES), ("unseen", UNSEEN_CATEGORIES),
                        ("unseen_cross", UNSEEN_CATEGORIES)):
        ce = category_rows(metrics, split, cats, kind="ce", methods=methods)
        if ce:
            parts += ["", f"## Cross-entropy, {split} split (lower is better)", "",
                      markdown_table(["method", *cats, "mean"], ce)]
    parts += surface_section(metrics, SPLIT_TITLES, methods)
    parts += paired_section(metrics)
    path = Path(out_dir) / "results.md"
    atomic_write_text(path, "\n".join(parts) + "\n")
    return path


def _ci(metrics: dict, key: str, suffix: str) -> str:
    lo, hi = metrics.get(f"{key}_lo{suffix}"), metrics.get(f"{key}_hi{suffix}")
    bounds = f" [{fmt(lo)}, {fmt(hi)}]" if lo is not None and lo == lo else ""
    return f"{fmt(metrics.get(key + suffix))}{bounds}"


def paired_section(metrics: dict) -> list[str]:
    """Paired per-sample comparison tables (``test/<split>/paired/...`` keys of
    :meth:`lit3d.completion.paired.PairedSamples.summary`), one per split."""
    parts = []
    for split, title in SPLIT_TITLES.items():
        base = f"test/{split}/paired"
        if f"{base}/n" not in metrics:
            continue
        cats = sorted({k.rsplit("/", 1)[1] for k in metrics if k.startswith(f"{base}/n/")})
        rows = []
        for label, suffix in [(c, f"/{c}") for c in cats] + [("all", "")]:
            rows.append([label, f"{int(metrics[f'{base}/n{suffix}'])}", _ci(metrics, f"{base}/model", suffix),
                         fmt(metrics.get(f"{base}/input{suffix}")), _ci(metrics, f"{base}/margin_input", suffix),
                         fmt(metrics.get(f"{base}/extrusion{suffix}")),
                         _ci(metrics, f"{base}/margin_extrusion", suffix)])
        parts += ["", f"## Paired comparison, {title}: per-sample IoU, mean [bootstrap 95% interval]", "",
                  markdown_table(["category", "n", "model", "input as prediction", "model - input",
                                  "silhouette extrusion", "model - extrusion"], rows)]
    if parts:
        parts += ["", "Same samples for every column; intervals resample samples (pairs for the margins), "
                      "2000 resamples, percentile method; none with fewer than 2 samples."]
    return parts


def write_figures(task, datamodule, out_dir: Path, n: int = 4, evaluation=None) -> list[Path]:
    """``completion_<split>.png`` per test split (:mod:`lit3d.completion.figures`: labelled shaded
    renders, input | stages | prediction | target, front and back views), ``max(1, n // 4)``
    samples per category; logged as ``eval/<split>`` images to a W&B logger when the task has one.

    The first sample of each split is also saved as voxel grids (``occupancy`` uint8 in
    ``<split>_prediction.npz`` / ``<split>_target.npz``) so that ``lit3d-score`` can
    compare them by rendering: ``lit3d-score same_target.npz same_prediction.npz``.
    """
    out_dir = Path(out_dir)
    paths = []
    task.eval()
    loaders = datamodule.test_dataloader()
    loaders = loaders if isinstance(loaders, list) else [loaders]
    names = list(getattr(datamodule, "test_split_names", [f"split{i}" for i in range(len(loaders))]))
    threshold = float(task.threshold)
    for name, loader in zip(names, loaders):
        samples = collect_samples(loader, max(1, n // 4))
        if not samples:
            continue
        with torch.no_grad():
            probs = task(samples[0]["input"][None].to(task.device)).cpu()
        _save_voxels(out_dir / f"{split_key(name)}_prediction.npz", probs[0, 0] >= threshold)
        _save_voxels(out_dir / f"{split_key(name)}_target.npz", samples[0]["target"][0] > 0.5)
        image = split_figure(task, samples, f"{split_key(name)} test split")
        path = out_dir / f"completion_{name}.png"
        buf = io.BytesIO()
        image.save(buf, format="PNG")
        atomic_write_bytes(path, buf.getvalue())
        paths.append(path)
        _log_image(task, f"eval/{split_key(name)}", image)
    return paths


def _log_image(task, key: str, image) -> None:
    """Log a PIL image to the task's W&B / TensorBoard loggers (none outside a trainer)."""
    try:
        loggers = task.loggers
    except RuntimeError:
        return
    log_image(loggers, key, image, task.global_step)


def _save_voxels(path: Path, occupancy: torch.Tensor) -> None:
    """(D, H, W) bool grid -> compressed .npz with key ``occupancy`` (uint8 0/1), atomically."""
    buf = io.BytesIO()
    np.savez_compressed(buf, occupancy=occupancy.cpu().numpy().astype(np.uint8))
    atomic_write_bytes(path, buf.getvalue())
