"""results.md and contact sheets for the canonical-form task, in the layout of thesis tables 5.1-5.4.

Thesis rows are the thesis's published retrieval figures (synthetic humans of SHREC'14, real
humans, TOSCA); ours are measured in this run on this run's data (which may be the built-in
synthetic figures): compare them only when the data is the same.
"""
from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import torch
from PIL import Image

from lit3d.reports.tables import fmt, markdown_table
from lit3d.utils.io import atomic_write_bytes, atomic_write_text

COLS = ("nn", "ft", "st", "dcg")
THESIS = {
    "5.1": ("synthetic humans (SHREC'14)", {
        "Classic MDS": (.10, .22, .39, .54), "Fast MDS": (.14, .20, .35, .53), "Non-metric MDS": (.09, .24, .41, .55),
        "Least Square MDS": (.01, .13, .31, .45), "Constrained MDS": (.04, .14, .25, .46), "GPS": (.40, .20, .32, .56),
        "Mesh Unfolding": (.04, .18, .34, .49), "Skeleton-based": (.01, .14, .32, .46), "Ours": (.51, .32, .41, .63)}),
    "5.2": ("real humans (SHREC'14), trained on synthetic", {
        "Classic MDS": (.01, .03, .07, .28), "GPS": (.07, .06, .12, .33), "Non-metric MDS": (.02, .04, .08, .30),
        "Ours": (.04, .023, .051, .23)}),
    "5.3": ("TOSCA", {
        "Classic MDS": (.74, .54, .80, .80), "Fast MDS": (.73, .52, .77, .77), "Non-metric MDS": (.76, .67, .87, .85),
        "Least Square MDS": (.79, .63, .86, .84), "Constrained MDS": (.88, .71, .89, .89), "GPS": (.71, .52, .72, .76),
        "Mesh Unfolding": (.88, .65, .86, .85), "Skeleton-based": (.78, .62, .85, .84), "Ours": (.91, .76, .80, .89)}),
}
ABLATION = {"Complete": (.91, .76, .80, .89), "without LFE": (.88, .62, .76, .84), "without MSFE": (.72, .48, .61, .73)}
OURS = (("lit3d model (ours)", "model"), ("posed input, no canonicalisation (ours)", "input"),
        ("true canonical depth, ceiling (ours)", "target"), ("classical MDS (ours)", "cmds"),
        ("SMACOF (ours)", "smacof"), ("GPS (ours)", "gps"), ("chance: random distances (ours)", "chance"))


def retrieval_rows(metrics: dict) -> list[list[str]]:
    rows = []
    for label, key in OURS:
        vals = [metrics.get(f"test/retrieval/{key}/{c}") for c in COLS]
        if all(v is None for v in vals):
            continue
        rows.append([label] + [fmt(v, 2) for v in vals])
    return rows


def write_results(metrics: dict, out_dir: Path, dataset: str | None = None) -> Path:
    """results.md: image metrics (model vs posed input), retrieval tables beside thesis tables 5.1-5.4."""
    m = metrics
    parts = ["# Canonical-form results", "",
             "Rows marked *(ours)* are measured in this run on this run's test split (held-out subjects and poses); "
             "thesis rows are the thesis's published figures on its data. Retrieval classes = subjects.", "",
             "## Canonical depth and mask (test)", "",
             markdown_table(["prediction", "masked depth MSE (lower is better)", "mask IoU"], [
                 ["lit3d model (ours)", fmt(m.get("test/depth_mse"), 4), fmt(m.get("test/iou"))],
                 ["posed input as its own canonical form (ours)", fmt(m.get("test/depth_mse_input"), 4),
                  fmt(m.get("test/iou_input"))]])]
    ours = retrieval_rows(m)
    for number, (title, rows) in THESIS.items():
        if dataset and dataset not in title.lower() and not (dataset == "synth" and number == "5.1"):
            continue
        table = [[f"{k} (thesis)"] + [fmt(v, 2) for v in vals] for k, vals in rows.items()] + ours
        parts += ["", f"## Table {number}: retrieval, {title}", "", markdown_table(["method", "NN", "FT", "ST", "DCG"], table)]
    parts += ["", "## Table 5.4: ablation on TOSCA (thesis); run `+sweep=canonical_ablation` for ours", "",
              markdown_table(["model", "NN", "FT", "ST", "DCG"],
                             [[f"{k} (thesis)"] + [fmt(v, 2) for v in vals] for k, vals in ABLATION.items()])]
    if m.get("test/retrieval/model/e") is not None:
        parts += ["", f"E-measure (ours): model {fmt(m.get('test/retrieval/model/e'), 2)}, "
                      f"input {fmt(m.get('test/retrieval/input/e'), 2)}, chance {fmt(m.get('test/retrieval/chance/e'), 2)}"]
    path = Path(out_dir) / "results.md"
    atomic_write_text(path, "\n".join(parts) + "\n")
    return path


def _png(path: Path, img: np.ndarray) -> Path:
    buf = io.BytesIO()
    Image.fromarray(img).save(buf, format="PNG")
    return atomic_write_bytes(path, buf.getvalue())


def write_figures(task, datamodule, out_dir: Path, n: int = 4) -> list[Path]:
    """One contact sheet per test subject: rows of input | predicted canonical | true canonical | error."""
    out_dir = Path(out_dir)
    task.eval()
    datamodule.setup("test")
    ds = datamodule.datasets["test"]
    by_subject: dict[str, list[int]] = {}
    for i, r in enumerate(ds.records):
        by_subject.setdefault(r["subject"], []).append(i)
    paths = []
    dev = next(task.parameters()).device
    for subject, idx in sorted(by_subject.items()):
        items = [ds[i] for i in idx[:n]]
        batch = {k: torch.stack([it[k] for it in items]).to(dev) for k in ("depth", "mask", "canon_depth", "canon_mask")}
        with torch.no_grad():
            out = task(batch["depth"], batch["mask"])
        paths.append(_png(out_dir / f"canonical_{subject}.png", task.panel(batch, out, n=len(items))))
    return paths
