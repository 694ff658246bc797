"""The surface-metric tables of results.md (keys of :mod:`lit3d.completion.surface_eval`): per test
split, one row per method (the model and each baseline, or the methods a folder was scored as),
IoU beside Chamfer-L1, the F-scores and normal consistency."""
from __future__ import annotations

import re
from collections.abc import Mapping, Sequence

from lit3d.metrics.surface import fscore_key
from lit3d.utils.tables import fmt, markdown_table

NOTE = ("Surfaces: marching cubes of the thresholded prediction and of the target grid, points sampled by area "
        "with a fixed seed, nearest neighbours both ways (docs/results_completion.md#surface-metrics). "
        "Conventions (docs/api.md#metrics): Chamfer-L1 = mean of unsquared nearest distances, the two "
        "directions averaged (not PyTorch3D's squared and added), in units of the grid side (lower is better); "
        "F-score@f with the threshold f x the target's bounding-box diagonal (not Tatarchenko et al.'s "
        "f x the volume side); normal consistency = mean |cos| between nearest points' normals, both directions. "
        "IoU is the per-sample mean of the tables above. 'empty': predictions with no occupied voxel "
        "(scored Chamfer sqrt(3), F 0, normals 0).")


def fscore_fractions(metrics: Mapping[str, float], split: str) -> list[float]:
    """The F-score fractions present among ``test/<split>/fscore_<f>pct...`` keys, ascending."""
    pattern = re.compile(rf"^test/{re.escape(split)}/fscore_([0-9.]+)pct[^/]*$")
    found = {float(m.group(1)) / 100 for k in metrics if (m := pattern.match(k))}
    return sorted(found)


def surface_section(metrics: Mapping[str, float], splits: Mapping[str, str],
                    rows: Sequence[tuple[str, str]]) -> list[str]:
    """Markdown lines: per split (``{split: title}``) with surface keys, a table of ``rows``
    (``(label, key suffix)``: ``""`` for the model, ``"_input"`` ...); empty when no split has them."""
    parts = []
    for split, title in splits.items():
        fractions = fscore_fractions(metrics, split)
        table = []
        for label, suffix in rows:
            chamfer = metrics.get(f"test/{split}/chamfer_l1{suffix}")
            if chamfer is None:
                continue
            empty = metrics.get(f"test/{split}/surface_empty{suffix}")
            table.append([label, fmt(metrics.get(f"test/{split}/iou{suffix}")), fmt(chamfer, 4)]
                         + [fmt(metrics.get(f"test/{split}/{fscore_key(f)}{suffix}")) for f in fractions]
                         + [fmt(metrics.get(f"test/{split}/normal_consistency{suffix}")),
                            "–" if empty is None else str(int(empty))])
        if table:
            header = ["method", "IoU", "Chamfer-L1 (lower better)", *[f"F-score@{100 * f:g}%" for f in fractions],
                      "normal consistency", "empty"]
            parts += ["", f"## Surface metrics, {title}", "", markdown_table(header, table)]
    if parts:
        parts += ["", NOTE]
    return parts
