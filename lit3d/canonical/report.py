"""results.md and contact sheets for the canonical-form task, in the layout of thesis tables 5.1-5.4.

Thesis rows are the thesis's published retrieval figures (synthetic humans of SHREC'14, real
humans, TOSCA); ours are measured in this run on this run's data (which may be the built-in
synthetic figures): compare them only when the data is the same.
"""
from __future__ import annotations

import io
from pathlib import Path


from lit3d.canonical.figures import subject_sheets
from lit3d.utils.data_hooks import NamesItsSource
from lit3d.utils.tables import fmt, markdown_table
from lit3d.utils.io import STAGE_PREFIX, atomic_write_bytes, atomic_write_text

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
OURS = (("lit3d model (ours)", "model"), ("plain U-Net, same data and losses (ours)", "unet"),
        ("posed input depth, no canonicalisation (ours)", "input"),
        ("posed input depth scored on its outline like the model row (evaluation.prediction_smooth_px) (ours)",
         "input_outline"),
        ("true canonical depth, one image per subject: 1.00 by construction (ours)", "target"),
        ("true canonical depth, camera turned up to ceiling_jitter_deg per item: the ceiling (ours)", "target_jitter"),
        ("classical MDS, full mesh (ours)", "cmds"), ("SMACOF (least-squares MDS), full mesh (ours)", "smacof"),
        ("non-metric MDS, full mesh (ours)", "nmds"), ("GPS, full mesh (ours)", "gps"),
        ("posed full mesh, no canonicalisation (ours)", "posed"),
        ("chance: random distances (ours)", "chance"))
MESH_KEYS = ("cmds", "smacof", "nmds", "gps", "posed")
# which thesis table a run's data belongs to (data.source)
TABLE_OF_SOURCE = {"synth": "5.1", "shrec14": "5.1", "tosca": "5.3"}


def retrieval_rows(metrics: dict) -> list[list[str]]:
    rows = []
    for label, key in OURS:
        vals = [metrics.get(f"test/retrieval/{key}/{c}") for c in COLS]
        if all(v is None for v in vals):
            continue
        rows.append([label] + [fmt(v, 2) for v in vals])
    return rows


def _dataset_from_run_dir(out_dir: Path) -> str | None:
    """``data.source.kind`` from the run dir's config.yaml (written by lit3d-train / lit3d-eval), if any; an
    evaluation's staging folder (:data:`lit3d.utils.io.STAGE_PREFIX`) reads its run dir's."""
    out_dir = Path(out_dir)
    run_dir = out_dir.parent if out_dir.name.startswith(STAGE_PREFIX) else out_dir
    path = run_dir / "config.yaml"
    if not path.is_file():
        return None
    try:
        import yaml

        cfg = yaml.safe_load(path.read_text()) or {}
        source = (cfg.get("data") or {}).get("source")
        return source.get("kind") if isinstance(source, dict) else source  # a config of either layout
    except Exception:
        return None


def write_results(metrics: dict, out_dir: Path, dataset: str | None = None) -> Path:
    """results.md: image metrics (model, U-Net, posed input) and retrieval rows (model, U-Net, posed
    input, true canonical, non-learned mesh baselines, chance) beside thesis tables 5.1-5.3; table 5.4.

    ``dataset`` (data.source.kind: synth, tosca, shrec14; default: read from ``out_dir/config.yaml``) puts
    our rows into the matching thesis table only (synth/SHREC'14 -> 5.1, TOSCA -> 5.3); unknown ->
    our rows in every table."""
    m = metrics
    dataset = dataset or _dataset_from_run_dir(out_dir)
    ours_in = TABLE_OF_SOURCE.get(dataset or "")
    image_rows = [["lit3d model (ours)", fmt(m.get("test/depth_mse"), 4), fmt(m.get("test/iou"))]]
    if m.get("test/depth_mse_unet") is not None:
        image_rows.append(["plain U-Net, same data and losses (ours)", fmt(m.get("test/depth_mse_unet"), 4),
                           fmt(m.get("test/iou_unet"))])
    image_rows.append(["posed input as its own canonical form (ours)", fmt(m.get("test/depth_mse_input"), 4),
                       fmt(m.get("test/iou_input"))])
    parts = ["# Canonical-form results", "",
             "Rows marked *(ours)* are measured in this run on this run's test split (held-out subjects and poses"
             + (f"; data: {dataset}" if dataset else "") + "); thesis rows are the thesis's published figures on "
             "its data. Retrieval classes = subjects.", "",
             "## Canonical depth and mask (test)", "",
             markdown_table(["prediction", "masked depth MSE (lower is better)", "mask IoU"], image_rows)]
    if m.get("test/depth_mse_unet") is not None:
        parts += ["", "The plain U-Net rows come from a run of its own on the same data, loss and alpha/beta "
                      "phases (`task.arch=unet`), merged by `python -m studies.canonical.report RUN_DIR --unet "
                      "UNET_RUN_DIR`."]
    ours = retrieval_rows(m)
    for number, (title, rows) in THESIS.items():
        table = [[f"{k} (thesis)"] + [fmt(v, 2) for v in vals] for k, vals in rows.items()]
        if ours_in is None or ours_in == number:
            table += ours
        parts += ["", f"## Table {number}: retrieval, {title}", "", markdown_table(["method", "NN", "FT", "ST", "DCG"], table)]
    notes = []
    if any(m.get(f"test/retrieval/{k}/nn") is not None for k in MESH_KEYS):
        secs = ", ".join(f"{k} {m[f'test/retrieval/{k}/seconds']:.1f}s" for k in MESH_KEYS
                         if m.get(f"test/retrieval/{k}/seconds") is not None)
        notes.append("*Full mesh* rows: the non-learned canonical forms of the test shapes' full meshes (one per "
                     "subject x pose, simplified to evaluation.baseline_max_vertices; geodesics by the heat method), "
                     "then the same descriptor; the depth rows rank every test item (subject x pose x view). "
                     + (f"Time per method (forms + descriptor): {secs}." if secs else ""))
    if m.get("test/retrieval/input_outline/nn") is not None:
        notes.append("The model row is scored on its outline: its depth smoothed inside its silhouette "
                     "(evaluation.prediction_smooth_px in config.yaml) before the descriptor; the outline row "
                     "scores the posed input the same way.")
    if m.get("test/retrieval/model/e") is not None:
        notes.append("E-measure (ours; F1 of the top min(32, n-1) results, so constant when every item is "
                     "within 32 ranks): " + ", ".join(
            f"{key} {fmt(m.get(f'test/retrieval/{key}/e'), 2)}" for _, key in OURS
            if m.get(f"test/retrieval/{key}/e") is not None))
    if notes:
        parts += [""] + [f"{n}  " if i < len(notes) - 1 else n for i, n in enumerate(notes)]
    parts += ["", "## Table 5.4: ablation on TOSCA (thesis); run `+sweep=canonical_ablation` for ours", "",
              markdown_table(["model", "NN", "FT", "ST", "DCG"],
                             [[f"{k} (thesis)"] + [fmt(v, 2) for v in vals] for k, vals in ABLATION.items()])]
    path = Path(out_dir) / "results.md"
    atomic_write_text(path, "\n".join(parts) + "\n")
    return path


POOLED_ROWS = (("lit3d model (ours)", "model"), ("plain U-Net, same data and losses (ours)", "unet"),
               ("posed input depth, no canonicalisation (ours)", "input"),
               ("true canonical depth, ceiling of the depth rows (ours)", "target"),
               ("warp oracle: true canonical where the posed view sees it, mean body elsewhere (ours)", "oracle"),
               ("Anny body fit, its canonical depth (lit3d.body_fit, ours)", "body_fit"),
               ("classical MDS, full mesh, landmark geodesics (ours)", "cmds"),
               ("SMACOF, full mesh, landmark geodesics (ours)", "smacof"),
               ("non-metric MDS, full mesh, landmark geodesics (ours)", "nmds"), ("GPS, full mesh (ours)", "gps"),
               ("posed full mesh, no canonicalisation (ours)", "posed"),
               ("ShapeDNA of the posed full mesh, intrinsic ceiling (ours)", "shapedna"),
               ("chance: random distances (ours)", "chance"))


def _mean_sd(pair) -> str:
    return f"{fmt(pair[0], 2)} ± {fmt(pair[1], 2)}"


def write_pooled_results(result: dict, out_dir: Path) -> Path:
    """``pooled_results.md``: the pooled cross-validated rows (:mod:`lit3d.canonical.pooled`, mean ± sd
    over the codebook seeds) beside the thesis's table for the data source (5.3 for TOSCA)."""
    summary = result["summary"]
    number = TABLE_OF_SOURCE.get((result.get("data") or {}).get("source") or "", "5.3")
    title, thesis = THESIS[number]
    table = [[f"{k} (thesis)"] + [fmt(v, 2) for v in vals[:3]] + ["–", fmt(vals[3], 2)] for k, vals in thesis.items()]
    known = {key for _, key in POOLED_ROWS}  # rows of other names (--depth-row ROW=DIR) before chance
    extra = [(f"{key}: depth images from --depth-row (ours)", key) for key in summary if key not in known]
    for label, key in (*POOLED_ROWS[:-1], *extra, POOLED_ROWS[-1]):
        if key in summary:
            table.append([label] + [_mean_sd(summary[key][c]) for c in ("nn", "ft", "st", "e", "dcg")])
    secs = ", ".join(f"{k} {v:.0f}s" for k, v in (result.get("seconds") or {}).items())
    d = result.get("data") or {}
    parts = [f"# Pooled cross-validated retrieval: table {number} ({title})", "",
             f"{result['n_items']} held-out items of {result['n_subjects']} subjects (data: {d.get('source')}, "
             f"{d.get('image_size')}², view_mode {d.get('view_mode', 'fixed')}, azimuths {d.get('azimuths')}, "
             f"split {d.get('split')}, {d.get('n_folds')} folds), every item scored once from the fold that held it "
             f"out; every row on the same items; mean ± sd over codebook seeds {result['seeds']}. "
             "Classes = subjects" + ("; every test subject is also in training (its other poses: a pose split). "
                                     if d.get("split") == "pose" else ". ")
             + "Thesis rows: the thesis's published figures on its data (no E reported).", "",
             markdown_table(["method", "NN", "FT", "ST", "E", "DCG"], table), "",
             f"Descriptor: {result.get('descriptor')}. Mesh rows: one per held-out subject x pose, full resolution "
             f"(settings {({k: v for k, v in (result.get('settings') or {}).items() if k.startswith('baseline')})}); "
             "ShapeDNA: first 30 cotangent-Laplacian eigenvalues x surface area, Euclidean distance after dividing "
             "each by 4 pi i (no codebook: sd 0). Chance: 100 random distance matrices per seed.", "",
             *_mask_match_lines(result.get("mask_match")),
             f"Time: {secs}; wall {result.get('wall_seconds', 0):.0f}s."]
    path = Path(out_dir) / "pooled_results.md"
    atomic_write_text(path, "\n".join(parts) + "\n")
    return path


def _mask_match_lines(match: dict | None) -> list[str]:
    """The descriptor-free mask checks of :func:`lit3d.canonical.pooled.mask_match`, one sentence."""
    if not match:
        return []
    parts = [f"{row} {v['iou']:.2f} IoU, nearest canonical mask of its own subject {v['nearest_subject']:.0%}, "
             f"retrieval by mask IoU NN {v['nn_by_mask']:.2f} / FT {v['ft_by_mask']:.2f}"
             + (f", IoU between its masks of one subject {v['iou_same']:.3f} against two subjects "
                f"{v['iou_other']:.3f}" if "iou_same" in v else "")
             for row, v in match.items()]
    return ["Masks, against the true canonical mask (no descriptor, no seed): " + "; ".join(parts) + ".", ""]


def write_figures(task, datamodule, out_dir: Path, n: int = 4, evaluation=None) -> list[Path]:
    """One contact sheet per test subject ``canonical_<subject>.png`` (:mod:`lit3d.canonical.figures`:
    posed input | predicted canonical (depth, shaded surface) | true canonical (depth, shaded
    surface) | |error|, one row per test pose/view). Also rewrites ``results.md`` for the
    datamodule's source when ``metrics.json`` is in ``out_dir`` (lit3d-eval writes them before the
    figures, without knowing the data source)."""
    import json

    out_dir = Path(out_dir)
    task.eval()
    datamodule.setup("test")
    paths = []
    for subject, sheet in subject_sheets(task, datamodule.datasets["test"], n).items():
        buf = io.BytesIO()
        sheet.save(buf, format="PNG")
        paths.append(atomic_write_bytes(out_dir / f"canonical_{subject}.png", buf.getvalue()))
    mpath = out_dir / "metrics.json"
    source = datamodule.source_kind if isinstance(datamodule, NamesItsSource) else None  # synth, tosca, ...
    if mpath.is_file() and source:
        write_results(json.loads(mpath.read_text()), out_dir, dataset=source)
    return paths
