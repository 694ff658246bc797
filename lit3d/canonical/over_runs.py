"""Mean ± sd over training runs of the pooled canonical results (training noise, not codebook noise):
``lit3d-summary --over-runs SWEEP_DIR... [--rows model input] [--out FILE.md] [--confusion ROW]``
(:mod:`lit3d.cli.summary_canonical`).

Each ``SWEEP_DIR`` is one whole cross-validation (``+sweep=canonical_cv``, or ``lit3d-summary --pooled``'s
``--out``) with the ``pooled.json`` that :mod:`lit3d.canonical.pooled` wrote; the runs differ by training seed
(or anything else the caller chooses to treat as noise). Per run and row, the score is that run's mean over its
codebook seeds; the table gives the mean and the sample sd (ddof 1) of those per-run means, with each run's
value, plus the same for the descriptor-free mask checks (``mask_match``). All runs must score the
same items (``n_items``) with the same codebook seeds, or the spread would mix protocols.
:func:`confusion`: which subject's true canonical mask is nearest (IoU) to each held-out prediction,
per true subject, summed over the runs (read from every fold's ``heldout.npz``): who is taken for whom.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from lit3d.canonical.heldout import pool
from lit3d.canonical.pooled import SCORES, canonical_masks, job_dirs, mean_sd, prediction_masks
from lit3d.metrics.retrieval import mask_iou
from lit3d.utils.tables import markdown_table

POOLED_KEYS = ("summary", "n_items", "seeds")  # what every pooled.json holds (lit3d.canonical.pooled.run)
MASK_KEYS = ("iou", "nearest_subject", "nn_by_mask", "ft_by_mask", "iou_same", "iou_other")


def load(sweep_dirs) -> list[dict]:
    """The ``pooled.json`` of every sweep dir; ValueError naming the file or dir when one is missing, is not
    a pooled result (not JSON, no :data:`POOLED_KEYS`) or the runs differ in items or codebook seeds."""
    runs = []
    for d in sweep_dirs:
        path = Path(d) / "pooled.json"
        if not path.is_file():
            raise ValueError(f"{path}: missing (run the sweep with +sweep=canonical_cv, or lit3d-summary --pooled "
                             "RUN_DIRS --out DIR)")
        try:
            run = json.loads(path.read_text(encoding="utf-8"))
        except (UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise ValueError(f"{path}: not a pooled result (not JSON: {exc})") from None
        missing = [k for k in POOLED_KEYS if not isinstance(run, dict) or k not in run]
        if missing:
            raise ValueError(f"{path}: not a pooled result (no {', '.join(missing)}; lit3d-summary --pooled writes one)")
        runs.append(run)
    for d, r in zip(sweep_dirs, runs):
        if (r["n_items"], r["seeds"]) != (runs[0]["n_items"], runs[0]["seeds"]):
            raise ValueError(f"{d}: {r['n_items']} items, codebook seeds {r['seeds']}; {sweep_dirs[0]} has "
                             f"{runs[0]['n_items']} items, seeds {runs[0]['seeds']}: not the same protocol")
    return runs


def _stats(values: list[float]) -> dict:
    mean, sd = mean_sd(values)
    return {"mean": mean, "sd": sd, "runs": [float(v) for v in values]}


def over_runs(runs: list[dict], rows=("model", "input")) -> dict:
    """``{"scores": {row: {score: {mean, sd, runs}}}, "masks": {row: {key: {mean, sd, runs}}}}``."""
    out: dict = {"scores": {}, "masks": {}}
    for row in rows:
        if all(row in r["summary"] for r in runs):
            out["scores"][row] = {s: _stats([r["summary"][row][s][0] for r in runs]) for s in SCORES}
        if all(row in r.get("mask_match", {}) for r in runs):
            out["masks"][row] = {k: _stats([r["mask_match"][row][k] for r in runs]) for k in MASK_KEYS
                                 if all(k in r["mask_match"][row] for r in runs)}  # older runs lack iou_same/other
    return out


def markdown(table: dict, names: list[str]) -> str:
    """Two tables: retrieval scores, then the mask checks; each cell ``mean ± sd (run values)``."""
    def cell(st):
        return f"{st['mean']:.2f} ± {st['sd']:.2f} ({' '.join(f'{x:.2f}' for x in st['runs'])})"

    parts = [f"Mean ± sd over {len(names)} runs ({', '.join(names)}); each run's value is its mean over "
             "codebook seeds.",
             markdown_table(["row", *(s.upper() for s in SCORES)],
                            [[row, *(cell(v[s]) for s in SCORES)] for row, v in table["scores"].items()])]
    if table["masks"]:
        parts.append(markdown_table(["row", *MASK_KEYS],
                                    [[row, *(cell(v[k]) if k in v else "–" for k in MASK_KEYS)]
                                     for row, v in table["masks"].items()]))
    return "\n\n".join(parts) + "\n"


def confusion(sweep_dirs, row: str = "model", mask_threshold: float = 0.5) -> tuple[list[str], np.ndarray]:
    """``(subject names, (C, C) counts)``: row = true subject, column = the subject whose true canonical
    mask is nearest to the prediction's mask, summed over the sweeps (each pooled over its folds)."""
    names, total = None, None
    for d in sweep_dirs:
        items = pool(job_dirs(Path(d)))
        masks = prediction_masks(items, mask_threshold)
        if row not in masks:
            raise ValueError(f"{d}: no row '{row}' in its held-out items (rows: {', '.join(masks)})")
        n, own, canon = canonical_masks(items)
        nearest = mask_iou(masks[row], canon).argmax(1)
        if names is not None and n != names:
            raise ValueError(f"{d}: subjects {n} differ from {names}")
        names = n
        counts = np.zeros((len(n), len(n)), dtype=int)
        np.add.at(counts, (own, nearest), 1)
        total = counts if total is None else total + counts
    return names, total


def confusion_markdown(names: list[str], counts: np.ndarray) -> str:
    """Counts table with each true subject's share recognised (its diagonal over its row)."""
    rows = [[name, *(str(int(c)) for c in counts[i]), f"{counts[i, i] / max(counts[i].sum(), 1):.2f}"]
            for i, name in enumerate(names)]
    overall = f"Overall: {np.trace(counts) / max(counts.sum(), 1):.2f} of {int(counts.sum())} predictions."
    return markdown_table(["true \\ nearest", *names, "own"], rows) + "\n\n" + overall + "\n"
