"""Evaluation on coloured point-cloud data in the CPCD2 layout (one reference, rated distortions).

    python -m studies.quality.cpcd2_study --root ../shared/data/cpcd2_phil [--out report.md]

Computes (or reads from the feature cache) the table of every rated pair with
:func:`lit3d.features.table.feature_table` (point clouds rendered as points), then reports
Spearman / Pearson correlations with MOS (every score oriented so that higher = better) on:

- ``all``: every rated stimulus;
- ``geometry``: stimuli whose geometry differs from the reference (``d1_mse > 0``);
- ``colour_only``: stimuli with the reference's geometry (``d1_mse == 0``), where only colour differs.

Rows: the **unlearned** overall score (mean Mask-SSIM, geometry and colour styles weighted
equally; nothing fitted), the point-cloud baselines (D1/D2/Y PSNR, Hausdorff, Chamfer), and the
10 single features with the highest |Spearman| on all stimuli — that ranking IS chosen on this
set (each feature's orientation is fixed a priori by its measure). The learned score's
leave-one-distortion-family-out figures (:func:`family_out`) are fitted on this set's other
families; the cross-dataset figure (train on the synthetic set) is not.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from datamodules.quality import QualityDataModule
from datamodules.quality.cpcd2 import read_cpcd2, stimulus_family
from lit3d.features.matrix import FeatureMatrix, TargetScaling
from lit3d.features.table import FeatureConfig, default_cache_dir, feature_config, feature_table, overall_score
from lit3d.quality.correlation import correlation_ci, pearson, spearman
from lit3d.quality.fusion import ChosenFusion, nested_group_out, out_of_group
from lit3d.quality.fusion_candidates import FEATURE_SETS, fusion_candidates, orientation
from lit3d.quality.protocol import LearnedScore
from lit3d.quality.shipped import model_document
from lit3d.quality.trainer import TrainConfig
from lit3d.utils.tables import markdown_table
from studies.quality.figure import write_figure

BASELINES = ("d1_psnr", "d2_psnr", "y_psnr", "pointssim_geometry", "pointssim_normal", "pointssim_curvature",
             "pointssim_colour", "pcqm", "hausdorff", "chamfer")
FAMILIES = {"G": "G-PCC", "V": "V-PCC", "N": "noise"}


def family(stimulus: str) -> str:
    """Distortion family of a CPCD2 stimulus name: ``phil_G_01`` -> ``G``."""
    return stimulus_family(stimulus)


def study_tables(root: str | Path, cfg: FeatureConfig | None = None, cache_dir=None, log=print):
    """``(items, tables)``: the reader's rated items and one feature dict per item (cached)."""
    ds = read_cpcd2(root)
    tables = []
    for it in ds.items:
        t = feature_table(it.reference, it.distorted, cfg, cache_dir=cache_dir)
        log(f"{it.name}: overall {t.overall_score():.4f} ({'cached' if t.cached else 'computed'})")
        tables.append(t.features)
    return ds.items, tables


def subsets(tables) -> dict[str, np.ndarray]:
    """Boolean row masks: ``all``, ``geometry`` (``d1_mse > 0``), ``colour_only`` (``d1_mse == 0``)."""
    d1 = np.array([t["d1_mse"] for t in tables])
    return {"all": np.ones(len(d1), bool), "geometry": d1 > 0, "colour_only": d1 == 0}


def correlation_rows(items, tables, top: int = 10) -> list[dict]:
    """One dict per score: name, kind, and ``spearman_<subset>`` / ``pearson_<subset>`` values."""
    mos = np.array([it.score for it in items])
    masks = subsets(tables)
    scores = {"overall (unlearned)": ("ours", np.array([overall_score(t) for t in tables]))}
    for b in BASELINES:
        if all(b in t for t in tables):
            scores[b] = ("baseline", orientation(b) * np.array([t[b] for t in tables]))
    common = sorted(set.intersection(*(set(t) for t in tables)) - set(BASELINES) - {"d1_mse", "d2_mse", "y_mse"})
    single = {n: orientation(n) * np.array([t[n] for t in tables]) for n in common}
    rho = {n: spearman(v, mos) for n, v in single.items() if np.ptp(v) > 0}
    for n in sorted(rho, key=lambda k: -abs(rho[k]))[:top]:
        scores[n] = ("single feature (top-10 chosen on this set)", single[n])
    rows = []
    for name, (kind, v) in scores.items():
        row = {"score": name, "kind": kind}
        for sub, m in masks.items():
            ok = m.sum() > 2
            row[f"spearman_{sub}"] = spearman(v[m], mos[m]) if ok else float("nan")
            row[f"pearson_{sub}"] = pearson(v[m], mos[m]) if ok else float("nan")
            row[f"n_{sub}"] = int(m.sum())
        rows.append(row)
    return rows


def study_matrix(items, tables, groups: str = "family") -> FeatureMatrix:
    """The set as a :class:`FeatureMatrix` (target: MOS 1..5 scaled to [0, 1], higher = worse);
    ``shapes`` holds the distortion family (``groups="family"``) or the cloud name."""
    mos = np.array([it.score for it in items])
    shapes = [family(it.name) if groups == "family" else it.shape for it in items]
    return FeatureMatrix.from_tables(tables, shapes, (5.0 - mos) / 4.0, [it.name for it in items],
                                     dataset="cpcd2", target_name="MOS")


def family_out(fm: FeatureMatrix, factory) -> dict[str, float]:
    """Leave-one-distortion-family-out: fit ``factory()`` on the other families, predict the held-out
    one. Returns the pooled Spearman / Pearson of the out-of-fold predictions with quality
    (prediction negated: the model predicts distortion) and the per-family Spearman."""
    pred = np.zeros(len(fm))
    out = {}
    for fam in fm.shape_names:
        model = factory().fit(fm.without_shape(fam))
        rows = fm.shapes == fam
        pred[rows] = model.predict(fm.rows(rows))
        out[f"spearman_{fam}"] = spearman(-pred[rows], -fm.target[rows]) if rows.sum() > 2 else float("nan")
    out["spearman_pooled"] = spearman(-pred, -fm.target)
    out["pearson_pooled"] = pearson(-pred, -fm.target)
    return out


def learned_factory(max_features: int = 6, candidates=None):
    """The learned score used here: SFS (Spearman on the training data) + the thesis MLP, SGD with
    momentum (lr 0.01, 150 epochs: the unit tests' fast set-up of the same model); ``candidates``
    restricts the features SFS may pick."""
    return lambda: LearnedScore(TrainConfig(lr=0.01, momentum=0.9, epochs=150), "sfs", criterion="train",
                                sfs_kind="spearman", max_features=max_features, candidates=candidates)


def family_candidates(names) -> list[str]:
    """SFS candidates of the family-out protocol: every Mask-SSIM feature and the baselines (a priori)."""
    return [n for n in names if n.startswith("mask_ssim/") or n in BASELINES]


def cross_from_synth(train: FeatureMatrix, items, tables, factory=None) -> dict[str, float]:
    """Train on ``train`` (e.g. the synthetic ordinal set), test on this set (nothing fitted here).
    Returns Spearman / Pearson of the prediction (negated: quality) with MOS per subset and the
    selected features."""
    factory = factory or learned_factory()
    common = [n for n in train.names if all(n in t for t in tables)]
    if not common:
        raise ValueError("cross_from_synth: the training set shares no feature with this set")
    model = factory().fit(train.select(common))
    test = study_matrix(items, tables, groups="cloud").select(common)
    q = -np.asarray(model.predict(test), dtype=np.float64)
    mos = np.array([it.score for it in items])
    out: dict = {"features": list(model.features)}
    for sub, m in subsets(tables).items():
        out[f"spearman_{sub}"] = spearman(q[m], mos[m]) if m.sum() > 2 else float("nan")
        out[f"pearson_{sub}"] = pearson(q[m], mos[m]) if m.sum() > 2 else float("nan")
    return out


def synth_matrix(feature_options: dict, data_dir: str | Path, n_levels: int | None = 3) -> FeatureMatrix:
    """The built-in synthetic ordinal set (``data=quality_synth``) with these feature options."""
    dm = QualityDataModule(data_dir=str(data_dir), source="synth", synth={"n_levels": n_levels},
                           feature_tables={"options": dict(feature_options)})
    return dm.load_matrix()


# --------------------------------------------------------------------------- rows with intervals
# the fusion's candidates (feature sets, anchor) are lit3d.quality.fusion_candidates': fixed before looking at any
# correlation; nested leave-one-family-out chooses among them, never the test family
FUSION_SETS = FEATURE_SETS  # the name the study's log uses


class PredictedOpinion:
    """The nested choice of :func:`fusion_candidates` whose held-out output is its predicted opinion (the chosen
    model's opinion map, fitted on the training families) instead of its score: ``predict`` -> ``(N,)`` distortion."""

    def __init__(self, candidates):
        self.chosen = ChosenFusion(candidates)

    def fit(self, train):
        self.chosen.fit(train)
        return self

    def predict(self, test):
        model = self.chosen.model
        return 1.0 - model.quality(test.columns(model.inputs))


def learned_predictions(items, tables, mlp: bool = True) -> dict[str, tuple[str, np.ndarray, dict]]:
    """Out-of-family predictions (quality: higher = better) of the learned scores, leave-one-family-out:
    ``{row name: (kind, (N,) values, details)}``. The fusion's kind, strength and feature set are chosen by
    leave-one-family-out inside the training families (nested); the thesis MLP + SFS (at most 3 features
    of :func:`family_candidates`) is fitted on the training families."""
    fm = study_matrix(items, tables)
    pred, choices = nested_group_out(fm, fusion_candidates(fm.names))
    out = {"learned fusion (ours, leave-one-family-out)": ("ours, learned", -pred, choices)}
    mapped = out_of_group(fm, lambda: PredictedOpinion(fusion_candidates(fm.names)))
    out["its predicted MOS (opinion map of the training families)"] = ("ours, learned", -mapped, {})
    if mlp:
        p = out_of_group(fm, learned_factory(3, family_candidates(fm.names)))
        out["thesis MLP + SFS (leave-one-family-out)"] = ("thesis model, learned", -p, {})
    return out


def score_columns(items, tables, learned: dict | None = None) -> dict[str, tuple[str, np.ndarray]]:
    """Every row of the interval tables: the unlearned score, each field baseline present, the learned rows."""
    scores = {"overall (unlearned)": ("ours, unlearned", np.array([overall_score(t) for t in tables]))}
    for b in BASELINES:
        if all(b in t for t in tables):
            scores[b] = ("baseline", orientation(b) * np.array([t[b] for t in tables]))
    for name, (kind, values, _) in (learned or {}).items():
        scores[name] = (kind, values)
    return scores


def interval_rows(items, tables, scores: dict, n_resamples: int = 2000) -> list[dict]:
    """Per score: SROCC / PLCC / KROCC with their 95% bootstrap intervals (stimuli resampled) on every
    subset (:func:`subsets`) and each distortion family (``family_G`` ...)."""
    mos = np.array([it.score for it in items])
    masks = dict(subsets(tables))
    fams = np.array([family(it.name) for it in items])
    masks.update({f"family_{f}": fams == f for f in FAMILIES if (fams == f).any()})
    rows = []
    for name, (kind, v) in scores.items():
        row = {"score": name, "kind": kind}
        for sub, m in masks.items():
            row[f"n_{sub}"] = int(m.sum())
            for c in ("srocc", "plcc", "krocc"):
                row[f"{c}_{sub}"] = correlation_ci(v[m], mos[m], c, n_resamples=n_resamples)
        rows.append(row)
    return rows


def interval_markdown(rows) -> str:
    """Three tables: all stimuli; the geometry / colour-only subsets; SROCC per family."""
    def cell(t):
        r, lo, hi = t
        return f"{r:.3f}" if not np.isfinite(lo) else f"{r:.3f} [{lo:.2f}, {hi:.2f}]"

    head = ["score", "kind"]
    first = rows[0]
    t1 = markdown_table(head + [f"{c.upper()} all (n={first['n_all']})" for c in ("srocc", "plcc", "krocc")],
                        [[r["score"], r["kind"]] + [cell(r[f"{c}_all"]) for c in ("srocc", "plcc", "krocc")]
                         for r in rows])
    subs = [("geometry", "geometry"), ("colour_only", "colour-only")]
    t2 = markdown_table(head + [f"{c.upper()} {lab} (n={first[f'n_{s}']})" for s, lab in subs
                                for c in ("srocc", "plcc", "krocc")],
                        [[r["score"], r["kind"]] + [cell(r[f"{c}_{s}"]) for s, _ in subs
                                                    for c in ("srocc", "plcc", "krocc")] for r in rows])
    fams = [f for f in FAMILIES if f"n_family_{f}" in first]
    t3 = markdown_table(head + [f"SROCC {FAMILIES[f]} (n={first[f'n_family_{f}']})" for f in fams],
                        [[r["score"], r["kind"]] + [cell(r[f"srocc_family_{f}"]) for f in fams] for r in rows])
    return "\n\n".join([t1, t2, t3])


def shipped_model(items, tables, feature_options: dict, cv_rows: list[dict], command: str) -> dict:
    """The shipped model's JSON (:func:`lit3d.quality.shipped.model_document`): the fusion candidate chosen by
    leave-one-family-out on every stimulus, fitted on all of them, with its cross-validated rows."""
    fm = study_matrix(items, tables)
    chosen = ChosenFusion(fusion_candidates(fm.names)).fit(fm)
    cv = {r["score"]: {k: v for k, v in r.items() if k not in ("score", "kind")} for r in cv_rows}
    return model_document("cpcd2-phil-fusion", f"CPCD2.0 phil ({len(items)} coloured point clouds, MOS 1..5)",
                          TargetScaling(1.0, 5.0, True, "MOS"), feature_options, chosen, cv, command)


def markdown(rows) -> str:
    subs = ("all", "geometry", "colour_only")
    head = ["score", "kind"] + [f"SROCC {s} (n={rows[0][f'n_{s}']})" for s in subs] + [f"PLCC {s}" for s in subs]
    body = [[r["score"], r["kind"]] + [f"{r[f'spearman_{s}']:.3f}" for s in subs]
            + [f"{r[f'pearson_{s}']:.3f}" for s in subs] for r in rows]
    return markdown_table(head, body)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m studies.quality.cpcd2_study", description=__doc__.split("\n\n")[0])
    p.add_argument("--root", required=True, help="dataset folder (mos.csv, Original/, Database_10/)")
    p.add_argument("--size", type=int, default=None, help="render size (default: the feature default, 256)")
    p.add_argument("--styles", default=None, help="comma-separated MatCap styles (default all)")
    p.add_argument("--measures", default=None, help="comma-separated image measures (default all)")
    p.add_argument("--learned", action="store_true",
                   help="also the learned score: leave-one-family-out here, and trained on the synthetic set")
    p.add_argument("--family-out", action="store_true",
                   help="also the learned score, leave-one-distortion-family-out (fitted on this set)")
    p.add_argument("--fusion", action="store_true",
                   help="the interval tables (SROCC/PLCC/KROCC with bootstrap intervals, subsets, families) with the "
                        "learned rows: the fusion (nested leave-one-family-out) and the thesis MLP + SFS")
    p.add_argument("--figure", metavar="PNG", default=None,
                   help="with --fusion: scatter panels of MOS against PCQM, Y-PSNR, the unlearned and the learned scores")
    p.add_argument("--ship", metavar="JSON", default=None,
                   help="with --fusion: write the chosen fusion, fitted on every stimulus, as a shipped model here")
    p.add_argument("--synth-dir", default="data/quality_synth_cpcd2", help="cache of the synthetic set (--learned)")
    p.add_argument("--out", default=None, help="write the markdown table here too")
    args = p.parse_args(argv)
    opts = {}
    if args.size:
        opts["size"] = args.size
    if args.styles:
        opts["styles"] = args.styles.split(",")
    if args.measures:
        opts["measures"] = args.measures.split(",")
    items, tables = study_tables(args.root, feature_config(opts), default_cache_dir())
    if args.fusion:
        learned = learned_predictions(items, tables)
        for name, (_, _, choices) in learned.items():
            for fam, c in choices.items():
                print(f"{name}, held-out family {fam}: chose {c['chosen']} {c.get('described', '')} (inner SROCC "
                      + ", ".join(f"{k} {v:.3f}" for k, v in c["scores"].items()) + ")")
        columns = score_columns(items, tables, learned)
        rows = interval_rows(items, tables, columns)
        text = interval_markdown(rows)
        if args.figure:
            keys = {"pcqm": "PCQM", "y_psnr": "Y-PSNR", "overall (unlearned)": "lit3d unlearned",
                    "learned fusion (ours, leave-one-family-out)": "lit3d learned, leave-one-family-out"}
            shown = {k: columns[k][1] for k in keys if k in columns}
            print("wrote", write_figure(args.figure, np.array([it.score for it in items]),
                                        [family(it.name) for it in items], shown, keys,
                                        "CPCD2 phil: 30 coloured point clouds, MOS against each score"))
        if args.ship:
            doc = shipped_model(items, tables, opts, rows, "python -m studies.quality.cpcd2_study --root ROOT --fusion "
                                "--ship " + args.ship)
            Path(args.ship).write_text(json.dumps(doc, indent=1) + "\n")
            print(f"wrote {args.ship}: {doc['chosen']}, {doc['described']}")
        print(text)
        if args.out:
            Path(args.out).write_text(text + "\n")
        return 0
    text = markdown(correlation_rows(items, tables))
    if args.family_out or args.learned:
        fm = study_matrix(items, tables)
        fam = family_out(fm, learned_factory(3, family_candidates(fm.names)))
        text += "\n\nlearned score, leave-one-distortion-family-out (FITTED on this set's other families): " + \
            ", ".join(f"{k} {v:.3f}" for k, v in fam.items())
    if args.learned:
        cross = cross_from_synth(synth_matrix(opts, args.synth_dir), items, tables)
        text += "\n\nlearned score trained on the synthetic ordinal set, tested here (not fitted here): " + \
            ", ".join(f"{k} {v:.3f}" for k, v in cross.items() if k != "features") + \
            f"; features {cross['features']}"
    print(text)
    if args.out:
        Path(args.out).write_text(text + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
