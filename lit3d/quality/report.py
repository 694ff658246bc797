"""results.md and scatter plots for shape quality, in the layout of thesis tables 4.2-4.4, 4.6-4.8.

Per-shape rows, method columns, the thesis's published figures in their own rows
beside ours. Thesis figures are Pearson correlations with human MOS on the named
dataset; ours are measured in this run on this run's data. On the synthetic set the
target is an *ordinal severity score*, not a human opinion score, so the two are
not comparable: the thesis rows are shown for layout only.

Metric keys read (see ``lit3d.quality.module`` and ``lit3d.quality.evaluator``):
``test/cv/<method>/<kind>/<shape>`` (leave-one-shape-out), ``test/<method>/<kind>/<shape>``
(held-out split of the checkpoint), ``test/cross/<dataset>/<method>/<kind>/<shape>``.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from lit3d.quality.correlation import pearson, spearman
from lit3d.utils.tables import fmt, markdown_table
from lit3d.utils.io import atomic_write_text

COLUMNS = ("chamfer", "hausdorff", "pointssim", "dcd", "mse", "psnr", "ms_ssim", "single_best", "ours_all", "ours_sfs")
HEADERS = {"chamfer": "Chamfer", "hausdorff": "Hausdorff", "pointssim": "PointSSIM", "dcd": "DCD", "mse": "MSE",
           "psnr": "PSNR", "ms_ssim": "MS-SSIM", "single_best": "single best feature", "ours_all": "Our (all)",
           "ours_sfs": "Our* (SFS)", "ours": "Our* (checkpoint)"}

_T = lambda *v: dict(zip(("chamfer", "hausdorff", "pointssim", "dcd", "mse", "psnr", "ms_ssim", "ours_all", "ours_sfs"), v))  # noqa: E731
THESIS = {
    "4.2": ("LIRIS/EPFL General-Purpose", {
        "armadillo": _T(.13, .13, .20, .12, .19, .17, .20, .41, .54),
        "dyno": _T(.02, .47, .67, .16, .17, .19, .34, .52, .54),
        "rockerarm": _T(.08, .27, .15, .23, .19, .18, .17, .36, .62),
        "venus": _T(.25, .13, .62, .40, .21, .20, .24, .36, .65),
        "average": _T(.12, .25, .41, .23, .19, .19, .23, .41, .58)}),
    "4.3": ("Guo et al. 2016", {
        "dwarf": _T(0, .16, .62, .19, .32, .31, .34, .75, .93),
        "hulk": _T(.35, .45, .65, .56, .35, .35, .46, .80, .87),
        "squirrel": _T(.31, .22, .17, .34, .26, .25, .36, .43, .63),
        "statue": _T(.05, .52, .92, .61, .31, .29, .38, .92, .93),
        "average": _T(.17, .33, .59, .43, .31, .30, .38, .72, .84)}),
    # table 4.4's body is missing from the thesis text; Our* and PointSSIM come from table 4.8
    "4.4": ("LIRIS Masking", {
        "armadillo": {"pointssim": .26, "ours_sfs": .51}, "dyno": {"pointssim": .41, "ours_sfs": .63},
        "lion": {"pointssim": .32, "ours_sfs": .64}, "bimba": {"pointssim": .22, "ours_sfs": .63},
        "average": {"pointssim": .30, "ours_sfs": .60}}),
}
THESIS_BATCHNORM = {"armadillo": (.42, .54), "dyno": (.52, .54), "rockerarm": (.56, .62), "venus": (.62, .65),
                    "average": (.53, .58)}  # table 4.6: (without, with)
THESIS_MASK_VARIANTS = {"mask_ssim": .33, "mask_ssim_window": .33, "mask_ssim_negative": .25, "mask_ssim_merge": .29}
THESIS_CROSS = {  # table 4.8: shape -> (within-dataset, cross-dataset, PointSSIM)
    "LIRIS Masking": {"armadillo": (.51, .43, .26), "dyno": (.63, .61, .41), "lion": (.64, .59, .32),
                      "bimba": (.63, .62, .22), "average": (.60, .58, .30)},
    "LIRIS/EPFL": {"armadillo": (.54, .53, .20), "dyno": (.54, .51, .67), "rockerarm": (.62, .62, .15),
                   "venus": (.65, .55, .62)},
}


def _methods(metrics: Mapping[str, float], prefix: str) -> list[str]:
    found = {k[len(prefix) + 1:].split("/")[0] for k in metrics
             if k.startswith(prefix + "/") and k.count("/") >= prefix.count("/") + 2}
    order = [c for c in (*COLUMNS, "ours") if c in found]
    return order + sorted(found - set(order) - {"cv", "cross", "n_features"})


def shape_table(metrics: Mapping[str, float], prefix: str, kind: str) -> tuple[list[str], list[list[str]]]:
    """Rows = shapes + average, columns = methods found under ``prefix``."""
    methods = [m for m in _methods(metrics, prefix) if f"{prefix}/{m}/{kind}" in metrics]
    shapes = list(dict.fromkeys(s for m in methods for s in _shapes_for(metrics, prefix, m, kind)))
    rows = [[s] + [fmt(metrics.get(f"{prefix}/{m}/{kind}/{s}"), 2) for m in methods] for s in shapes]
    rows.append(["average"] + [fmt(metrics.get(f"{prefix}/{m}/{kind}"), 2) for m in methods])
    return ["shape"] + [HEADERS.get(m, m) for m in methods], rows


def _shapes_for(metrics, prefix, method, kind):
    p = f"{prefix}/{method}/{kind}/"
    return [k[len(p):] for k in metrics if k.startswith(p) and "/" not in k[len(p):]]


def which_thesis_table(shapes: Sequence[str]) -> str | None:
    low = {s.lower() for s in shapes}
    best, overlap = None, 0
    for number, (_, rows) in THESIS.items():
        o = len(low & set(rows) - {"average"})
        if o > overlap:
            best, overlap = number, o
    return best if overlap >= 2 else None


def thesis_rows(number: str, methods: Sequence[str]) -> list[list[str]]:
    _, rows = THESIS[number]
    return [[f"{s} (thesis)"] + [fmt(vals.get(m), 2) for m in methods] for s, vals in rows.items()]


def write_results(metrics: dict, out_dir: Path) -> Path:
    """results.md: LOSO tables (4.2-4.4 layout), held-out split, cross-dataset (4.8), thesis rows beside ours."""
    parts = ["# Shape quality results", "",
             "Correlation of each method's score with the target, per test shape and averaged over shapes. "
             "Targets and scores are oriented 'higher = more distorted' (similarity measures negated), so higher "
             "correlation is better. Rows marked *(thesis)* are the thesis's published Pearson correlations with "
             "human MOS on the named dataset; the others are measured in this run on this run's data.",
             "On the built-in synthetic set the target is an **ordinal severity score** (level within a "
             "distortion type), not a human opinion score: there the thesis rows only show the layout."]
    if "test/n_features" in metrics:
        parts.append(f"\nFeatures used by the checkpoint: {int(metrics['test/n_features'])}.")
    for kind in ("pearson", "spearman"):
        if any(k.startswith("test/cv/") for k in metrics):
            header, rows = shape_table(metrics, "test/cv", kind)
            shapes = [r[0] for r in rows[:-1]]
            number = which_thesis_table(shapes)
            title = f"Leave-one-shape-out cross-validation, {kind.title()}"
            if number:
                title += f" (thesis table {number}: {THESIS[number][0]})"
                methods = [m for m in _methods(metrics, "test/cv") if f"test/cv/{m}/{kind}" in metrics]
                extra_methods = ["pointssim", "dcd"]
                header = header + [HEADERS[m] for m in extra_methods]
                rows = [r + ["–"] * len(extra_methods) for r in rows]
                rows += thesis_rows(number, methods + extra_methods) if kind == "pearson" else []
            parts += ["", f"## {title}", "", markdown_table(header, rows)]
        if any(k.startswith("test/ours/") for k in metrics):
            header, rows = shape_table(metrics, "test", kind)
            parts += ["", f"## Checkpoint on its held-out test shapes, {kind.title()}", "",
                      "Baselines and the single best feature chosen on the checkpoint's training shapes.", "",
                      markdown_table(header, rows)]
    cross = sorted({k.split("/")[2] for k in metrics if k.startswith("test/cross/")})
    for dname in cross:
        header, rows = shape_table(metrics, f"test/cross/{dname}", "pearson")
        parts += ["", f"## Cross-dataset (thesis table 4.8 layout): trained on this run's data, tested on {dname}", "",
                  markdown_table(header, rows)]
    if cross:
        trows = [[f"{s} ({ds}, thesis)", fmt(w, 2), fmt(c, 2), fmt(p, 2)]
                 for ds, rows_ in THESIS_CROSS.items() for s, (w, c, p) in rows_.items()]
        parts += ["", "Thesis table 4.8 (trained on Guo 2016):", "",
                  markdown_table(["shape", "within-dataset", "cross-dataset", "PointSSIM"], trows)]
    parts += ["", "## Thesis ablations (for the sweeps `quality_batchnorm`, `quality_mask_variants`)", "",
              markdown_table(["shape", "without batch-norm (thesis 4.6)", "with batch-norm (thesis 4.6)"],
                             [[s, fmt(a, 2), fmt(b, 2)] for s, (a, b) in THESIS_BATCHNORM.items()]), "",
              markdown_table(["Mask-SSIM variant", "average Pearson (thesis 4.7)"],
                             [[k, fmt(v, 2)] for k, v in THESIS_MASK_VARIANTS.items()])]
    path = Path(out_dir) / "results.md"
    atomic_write_text(path, "\n".join(parts) + "\n")
    return path


# --------------------------------------------------------------------------- figures
def scatter_png(groups: Mapping[str, tuple[np.ndarray, np.ndarray]], path: Path, title: str = "",
                size: int = 220) -> Path:
    """One panel per shape: x = target, y = prediction, both rescaled to the panel (PIL only)."""
    from PIL import Image, ImageDraw

    n = max(len(groups), 1)
    pad = 28
    img = Image.new("RGB", (n * size, size + 18), "white")
    d = ImageDraw.Draw(img)
    if title:
        d.text((4, 2), title, fill="black")
    for i, (shape, (t, p)) in enumerate(groups.items()):
        x0, y0 = i * size, 18
        d.rectangle([x0 + pad, y0 + 4, x0 + size - 6, y0 + size - pad], outline="grey")
        t, p = np.asarray(t, float), np.asarray(p, float)
        if t.size:
            tl, th = float(t.min()), float(t.max())
            pl_, ph = float(p.min()), float(p.max())
            w, h = size - pad - 12, size - pad - 10
            for a, b in zip(t, p):
                px = x0 + pad + 3 + (a - tl) / max(th - tl, 1e-12) * w
                py = y0 + size - pad - 3 - (b - pl_) / max(ph - pl_, 1e-12) * h
                d.ellipse([px - 2.5, py - 2.5, px + 2.5, py + 2.5], fill=(200, 60, 40))
            d.text((x0 + pad, y0 + size - pad + 4), f"{shape}  r={pearson(p, t):.2f} rho={spearman(p, t):.2f}",
                   fill="black")
        d.text((x0 + 2, y0 + size // 2), "pred", fill="grey")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    img.save(path)
    return path


def write_scatter_figures(ours: Mapping[str, np.ndarray] | None, cv_results: Mapping | None,
                          out_dir: Path) -> list[Path]:
    """Scatter plots of predicted vs target per test shape: the checkpoint on its held-out shapes
    (``ours``: ``{"pred", "target", "shapes"}`` arrays of one length) and each learned
    leave-one-shape-out method in ``cv_results`` (method -> ``protocol.EvalResult``)."""
    out_dir = Path(out_dir)
    paths = []
    if ours is not None:
        shapes = np.asarray(ours["shapes"]).astype(str)
        groups = {s: (ours["target"][shapes == s], ours["pred"][shapes == s]) for s in dict.fromkeys(shapes.tolist())}
        paths.append(scatter_png(groups, out_dir / "quality_scatter_checkpoint.png",
                                 "checkpoint: prediction vs target (x) per held-out shape"))
    for method in ("ours_sfs", "ours_all"):
        if method in (cv_results or {}):
            groups = {s: (r.target, r.pred) for s, r in cv_results[method].per_shape.items()}
            paths.append(scatter_png(groups, out_dir / f"quality_scatter_cv_{method}.png",
                                     f"leave-one-shape-out {method}: prediction vs target (x)"))
    return paths
