"""The body fit's tables: spreads (median, quartiles) of :mod:`lit3d.body.fit_scores`' measures per
method, and their markdown (``results.md`` of ``lit3d-eval`` on a body checkpoint, ``body_eval.md``
of ``python -m studies.body.evaluate``)."""
from __future__ import annotations

import numpy as np

from lit3d.body.fit_scores import methods_in
from lit3d.body_fit.model import PHENOTYPES


# ------------------------------------------------------------------ report
def spread(values) -> dict[str, float]:
    """Median, quartiles, mean, min, max of ``values``."""
    v = np.asarray(values, float)
    return {"median": float(np.median(v)), "q25": float(np.percentile(v, 25)), "q75": float(np.percentile(v, 75)),
            "mean": float(v.mean()), "min": float(v.min()), "max": float(v.max()), "n": int(len(v))}


def _cell(s: dict, fmt: str = ".0f") -> str:
    return f"{s['median']:{fmt}} [{s['q25']:{fmt}}-{s['q75']:{fmt}}]"


def summarise(anny: list[dict], faust: list[dict]) -> dict:
    """Spreads of every measure per method."""

    out: dict = {}
    if anny:
        out["anny"] = {m: {"canonical_mm": spread([r[m]["canonical_mm"] for r in anny]),
                           "posed_mm": spread([r[m]["posed_mm"] for r in anny]),
                           "phenotype_abs": {k: spread([r[m]["phenotype_abs"][k] for r in anny]) for k in PHENOTYPES}}
                       for m in methods_in(anny[0])}
        out["anny"]["cpu_s"] = spread([r["cpu_s"] for r in anny])
    if faust:
        keys = ("chamfer", "f@0.017", "f@0.034", "pred_to_truth", "truth_to_pred")
        out["faust"] = {m: {k: spread([r[m][k] for r in faust]) for k in keys} for m in (*methods_in(faust[0]), "points")}
        out["faust"]["cpu_s"] = spread([r["cpu_s"] for r in faust])
        out["faust"]["poor_fit"] = int(sum(r["poor_fit"] for r in faust))
    for task, rows in (("anny", anny), ("faust", faust)):
        for m in ("init", "refined"):
            if rows and m in rows[0]:
                out[task][m]["cpu_s"] = spread([r[m]["cpu_s"] for r in rows])
                if task == "faust":
                    out[task][m]["poor_fit"] = int(sum(r[m]["poor_fit"] for r in rows))
    return out


def _labels(meta: dict, faust: bool = False) -> dict[str, str]:
    alone = "optimisation alone: " if "init" in meta else ""
    return {"fit": alone + ("Anny fit, posed body" if faust else "Anny fit") + f" ({meta['starts']})",
            "init": "regressor alone", "refined": f"regressor + refinement ({meta.get('refine', '')})",
            "points": "visible input points", "mean": "mean body (placed, scaled)"}


def _seconds(s: dict, m: str) -> str:
    c = s["cpu_s"] if m == "fit" else s[m].get("cpu_s")
    return "-" if c is None else f"{c['median']:.2f} [{c['q25']:.2f}-{c['q75']:.2f}]"


def markdown(summary: dict, meta: dict) -> str:
    """The tables of ``summary`` (medians with [quartiles])."""

    lines = [f"# Anny body fit evaluation\n\n`{meta['command']}`\n"]
    if "anny" in summary:
        a = summary["anny"]
        lines += [f"## Held-out Anny people (N = {a['cpu_s']['n']}, body_seed {meta['body_seed']}, pose_seed "
                  f"{meta['pose_seed']}, sensor {meta['sensor']})\n",
                  "Median over people of each person's median per-vertex error (mm), [quartiles over people]; "
                  "phenotype: mean over people of |error| (phenotype units, [0, 1]).\n",
                  "| method | canonical body (mm) | posed body (mm) | " + " | ".join(PHENOTYPES) + " | CPU s/image |",
                  "|---" * (4 + len(PHENOTYPES)) + "|"]
        for m in ("fit", "init", "refined", "mean"):
            if m not in a:
                continue
            ph = " | ".join(f"{a[m]['phenotype_abs'][k]['mean']:.3f}" for k in PHENOTYPES)
            lines.append(f"| {_labels(meta)[m]} | {_cell(a[m]['canonical_mm'])} | {_cell(a[m]['posed_mm'])} | {ph} | "
                         f"{_seconds(a, m)} |")
        c = a["cpu_s"]
        lines.append(f"\nFit CPU time per image: median {c['median']:.1f} s (range {c['min']:.1f}-{c['max']:.1f}).\n")
    if "faust" in summary:
        f = summary["faust"]
        lines += [f"## FAUST faust_a (N = {f['cpu_s']['n']}, 1.7 m, front view, whole surface as truth)\n",
                  "Median [quartiles] over meshes; Chamfer = mean of the two directed mean distances (mm); "
                  "F-score at 17 mm (1%) and 34 mm (2%).\n",
                  "| method | Chamfer (mm) | F@1% | F@2% | pred->truth (mm) | truth->pred (mm) | CPU s/image |",
                  "|---|---|---|---|---|---|---|"]
        for m in ("fit", "init", "refined", "points", "mean"):
            if m not in f:
                continue
            lines.append(f"| {_labels(meta, True)[m]} | {_cell(f[m]['chamfer'])} | {_cell(f[m]['f@0.017'], '.2f')} | "
                         f"{_cell(f[m]['f@0.034'], '.2f')} | {_cell(f[m]['pred_to_truth'])} | {_cell(f[m]['truth_to_pred'])} "
                         f"| {_seconds(f, m) if m != 'points' else '-'} |")
        c = f["cpu_s"]
        lines.append(f"\nFit CPU time per image: median {c['median']:.1f} s (range {c['min']:.1f}-{c['max']:.1f}); "
                     f"flagged poor_fit: {f['poor_fit']} of {c['n']}"
                     + "".join(f"; {_labels(meta)[m]}: {f[m]['poor_fit']}" for m in ("init", "refined") if m in f) + ".\n")
    return "\n".join(lines)
