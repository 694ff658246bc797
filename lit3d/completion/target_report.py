"""``results.md`` of ``lit3d-eval-folder PRED_DIR --targets TARGET_DIR``: the means over the pairs with
their 95% intervals, the conventions of every measure (also written into metrics.json), and one row
per pair. The measures: :mod:`lit3d.completion.target_scores`."""
from __future__ import annotations

from collections.abc import Sequence

from lit3d.completion.target_scores import TargetScoring, measure_keys
from lit3d.metrics.bootstrap import N_RESAMPLES

LABELS = {"chamfer_l1": "Chamfer-L1 (lower better)", "chamfer_l2": "Chamfer-L2 (lower better)",
          "normal_consistency": "normal consistency", "iou": "IoU"}


def measure_label(key: str) -> str:
    """The table label of a measure: ``fscore_1pct`` -> ``F-score@1%``."""
    if key.startswith("fscore_") and key.endswith("pct"):
        return f"F-score@{key[len('fscore_'):-len('pct')]}%"
    return LABELS.get(key, key)


def conventions(cfg: TargetScoring) -> dict[str, str]:
    """One sentence per convention of the scoring ``cfg``: the notes of results.md and metrics.json."""
    frame = {"unit": "unit: the grid is the cube [-0.5, 0.5]³", "voxel": "voxel: vertex (x, y, z) at grid index [x, y, z]"}
    return {
        "pairing": "PRED_DIR/<stem>.<ext> with TARGET_DIR/<stem>.<ext> (meshes .obj/.ply/.off, grids .npz/.npy; "
                   "the extensions may differ)",
        "frame": "meshes as stored: nothing is centred, scaled or aligned, so distances are in the targets' units; "
                 f"a grid's surface is its marching-cubes mesh in the '{cfg.mesh_frame}' frame ({frame[cfg.mesh_frame]}); "
                 f"prediction grids occupied at >= {cfg.threshold:g}, target grids at >= 0.5",
        "samples": f"{cfg.points} points uniformly by area on each surface, seed {cfg.seed} for both",
        "chamfer_l1": "(mean d(pred→target) + mean d(target→pred)) / 2: unsquared nearest-point distances, "
                      "the two directions averaged (halved), in the targets' units",
        "chamfer_l2": "mean d(pred→target)² + mean d(target→pred)²: squared distances, the two directions summed "
                      "(PyTorch3D's chamfer_distance defaults), in squared units",
        "fscore": "2PR / (P + R) at the distance f × the diagonal of the target surface's bounding box (f a share of "
                  "that diagonal, not of a volume side); P: the share of predicted points within that distance of "
                  "the target, R: the share of target points within it of the prediction",
        "normal_consistency": "mean |cos| between each point's face normal and its nearest neighbour's, both "
                              "directions (unoriented; 1 = parallel)",
        "iou": "volumetric, for pairs of solids only (grids, or meshes watertight after merging coincident vertices): "
               f"two meshes voxelised (surface voxels + enclosed inside) on one {cfg.resolution}³ cube grid holding "
               "both bounding boxes, a mesh beside a grid on the grid's own voxels",
        "interval": f"95% percentile bootstrap interval of the mean over the pairs ({N_RESAMPLES} resamples, "
                    f"seed {cfg.seed}); none with fewer than 2 pairs",
    }


def _number(key: str, value: float | None) -> str:
    if value is None:
        return "–"
    return f"{value:.4g}" if key.startswith("chamfer") else f"{value:.3f}"


def results_text(name: str, pred_dir: str, target_dir: str, rows: Sequence[dict], means: dict[str, dict],
                 cfg: TargetScoring, unpaired: Sequence[str] = ()) -> str:
    """The page: a title, the means table with its conventions, then the per-pair table."""
    keys = measure_keys(cfg.fscore_at)
    kinds = ", ".join(f"{sum(r['kinds'] == k for r in rows)} {k}" for k in sorted({r["kinds"] for r in rows}))
    notes = conventions(cfg)
    lines = [f"# {name} against the targets of {target_dir}", "",
             f"Predictions of {name} from {pred_dir}, paired with the targets of {target_dir} by file stem: "
             f"{len(rows)} pairs (prediction/target: {kinds})."
             + (f" Not scored, no target of their stem: {', '.join(unpaired)}." if unpaired else ""), "",
             "## Means over the pairs", "",
             "| measure | mean | 95% interval | pairs |", "|---|---|---|---|"]
    for key in keys:
        m = means[key]
        interval = "–" if m["low"] is None else f"[{_number(key, m['low'])}, {_number(key, m['high'])}]"
        lines.append(f"| {measure_label(key)} | {_number(key, m['mean'])} | {interval} | {m['pairs']} |")
    skipped = sorted({r["iou_skipped"] for r in rows if r.get("iou_skipped")})
    lines += ["", "Conventions:", ""]
    lines += [f"- **{label}**: {notes[k]}" for k, label in (
        ("pairing", "pairs"), ("frame", "frame and units"), ("samples", "surface samples"),
        ("chamfer_l1", "Chamfer-L1"), ("chamfer_l2", "Chamfer-L2"), ("fscore", "F-score@f"),
        ("normal_consistency", "normal consistency"), ("iou", "IoU"), ("interval", "intervals"))]
    if skipped:
        lines.append(f"- IoU not measured for {sum(bool(r.get('iou_skipped')) for r in rows)} pairs: {'; '.join(skipped)}")
    lines += ["", "## Per pair", "",
              "| stem | prediction | target | " + " | ".join(measure_label(k) for k in keys) + " |",
              "|---|---|---|" + "---|" * len(keys)]
    for r in rows:
        lines.append(f"| {r['stem']} | {r['prediction']} | {r['target']} | "
                     + " | ".join(_number(k, r.get(k)) for k in keys) + " |")
    return "\n".join(lines) + "\n"


__all__ = ["conventions", "measure_label", "results_text"]
