"""The body task's evaluator (interface: :mod:`lit3d.runtime.registry`): after ``trainer.test`` (the
regressor's loss and errors on the test draw), the body fit from the regressor's start on held-out
people, as ``docs/reconstruct.md`` reports it (:mod:`lit3d.body.fit_scores`):

- ``anny_people`` held-out Anny people (draws ``body_seed`` / ``pose_seed``, pose mix ``poses``,
  ``sensor`` noise): canonical and posed per-vertex errors, phenotype errors, CPU seconds;
- with ``data.faust_root`` set: every FAUST scan seen from the front (``faust_limit``: the first K),
  Chamfer and F-scores against the whole surface on ``samples`` points a mesh.

Rows: the regressor alone, the regressor + refinement (``refine_global`` + ``refine_full`` steps),
the mean body, and with ``alone: true`` the optimisation from the mean body (slow: ~6-8 s a person).
Metrics: ``test/<set>/<method>/<measure>`` medians, with ``_q25`` / ``_q75`` beside them.
"""
from __future__ import annotations

import json
import logging
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from lit3d.body.figures import write_fit_sheet
from lit3d.body.fit_scores import anny_items, faust_items
from lit3d.body.report import markdown, summarise
from lit3d.body_fit.regressor import refine_config
from lit3d.body_fit.synthetic import Camera
from lit3d.utils.evaluation import Evaluation
from lit3d.utils.io import atomic_write_text

log = logging.getLogger(__name__)

DEFAULTS = {"anny_people": 20, "body_seed": 1000, "pose_seed": 1000, "poses": "upright", "sensor": "recgan",
            "refine_global": 10, "refine_full": 30, "samples": 20000, "faust_limit": 0, "alone": False}
SPREAD = ("median", "q25", "q75")


def _settings(settings: Mapping) -> dict:
    unknown = sorted(set(settings) - set(DEFAULTS))
    if unknown:
        raise ValueError(f"evaluation.{unknown[0]}: not a body evaluation setting (known: {', '.join(DEFAULTS)})")
    return {**DEFAULTS, **dict(settings)}


def prepare(task, settings: Mapping) -> None:
    """Nothing to set up before the test."""
    _settings(settings)


def flat_metrics(summary: dict) -> dict[str, float]:
    """``test/<set>/<method>/<measure>[_q25|_q75]`` from :func:`lit3d.body.report.summarise`'s spreads."""
    out: dict[str, float] = {}
    for name, methods in summary.items():
        for method, measures in methods.items():
            if not isinstance(measures, dict):
                out[f"test/{name}/{method}"] = float(measures)
                continue
            if "median" in measures:  # the set's own spread (cpu_s)
                for stat in SPREAD:
                    out[f"test/{name}/{method}" + ("" if stat == "median" else f"_{stat}")] = measures[stat]
                continue
            for measure, spread in measures.items():
                if measure == "phenotype_abs":
                    for label, s in spread.items():
                        out[f"test/{name}/{method}/phenotype_abs/{label}"] = s["mean"]
                elif isinstance(spread, dict):
                    key = f"test/{name}/{method}/{measure}".replace("f@0.017", "f@1%").replace("f@0.034", "f@2%")
                    for stat in SPREAD:
                        out[key + ("" if stat == "median" else f"_{stat}")] = spread[stat]
                else:
                    out[f"test/{name}/{method}/{measure}"] = float(spread)
    return out


def protocol(task, datamodule, settings: Mapping) -> Evaluation:
    """The body fit from ``task``'s regressor on held-out Anny people and, with ``data.faust_root``, FAUST."""
    s = _settings(settings)
    body, cam = datamodule.anny_body(), Camera.default()
    init = (task.regressor(), refine_config(s["refine_global"], s["refine_full"]))
    meta = {"command": "lit3d-eval (the body task's evaluation)", "body_seed": s["body_seed"], "pose_seed": s["pose_seed"],
            "sensor": s["sensor"], "poses": s["poses"], "settings": s,
            "starts": "one start: the mean body", "refine": f"{s['refine_global']} + {s['refine_full']} steps"}
    anny = anny_items(body, s["anny_people"], s["body_seed"], s["pose_seed"], cam, s["sensor"], log.info,
                      init=init, poses=s["poses"], alone=s["alone"]) if s["anny_people"] else []
    faust_root = datamodule.faust_root
    faust = faust_items(body, Path(faust_root), cam, s["samples"], None, log.info, s["faust_limit"], init=init,
                        alone=s["alone"]) if faust_root else []
    summary = summarise(anny, faust)
    return Evaluation(flat_metrics(summary), {"summary": summary, "meta": meta, "anny": anny, "faust": faust,
                                              "settings": s})


def write_artefacts(evaluation: Evaluation, out_dir: Path) -> list[Path]:
    """``body_eval.json`` (every person and scan) and ``body_eval.md`` (the tables with quartiles)."""
    a = evaluation.artefacts
    if not a:
        return []
    out_dir = Path(out_dir)
    js = atomic_write_text(out_dir / "body_eval.json", json.dumps(
        {k: a[k] for k in ("meta", "summary", "anny", "faust")}, indent=1, default=_plain))
    md = atomic_write_text(out_dir / "body_eval.md", markdown(a["summary"], a["meta"]))
    return [js, md]


def validation_protocol(trainer, task, datamodule, settings: Mapping) -> Evaluation:
    """``lit3d-eval split=val``: nothing beyond the module's own ``val/`` metrics."""
    return Evaluation()


def _plain(value):
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"not JSON: {type(value).__name__}")


def write_results(metrics: Mapping[str, float], out_dir: Path) -> Path:
    """``results.md``: the regressor's test errors and the fit's medians [quartiles] per set and method."""
    lines = ["# Body regressor: evaluation", "",
             "The network alone on the test draw (mean over people):", "",
             "| loss | phenotype MAE | joint-angle MAE (rad) | translation MAE (m) |", "|---|---|---|---|",
             "| " + " | ".join(_num(metrics.get(f"test/{k}")) for k in ("loss", "phenotype_mae", "theta_mae",
                                                                         "translation_mae_m")) + " |", ""]
    rows = {"refined": "regressor + refinement", "init": "regressor alone", "fit": "optimisation alone", "mean": "mean body"}
    tables = {"anny": ("held-out Anny people", [("canonical_mm", "canonical body (mm)"), ("posed_mm", "posed body (mm)"),
                                                ("cpu_s", "CPU s/image")]),
              "faust": ("FAUST scans", [("chamfer", "Chamfer (mm)"), ("f@1%", "F@1%"), ("f@2%", "F@2%"),
                                        ("cpu_s", "CPU s/image")])}
    for name, (title, cols) in tables.items():
        present = [m for m in rows if f"test/{name}/{m}/{cols[0][0]}" in metrics]
        if not present:
            continue
        lines += [f"## {title} (median [quartiles])", "", "| method | " + " | ".join(c for _, c in cols) + " |",
                  "|---" * (len(cols) + 1) + "|"]
        for m in present:
            lines.append(f"| {rows[m]} | " + " | ".join(_spread(metrics, f"test/{name}/{m}/{k}") for k, _ in cols) + " |")
        lines.append("")
    return atomic_write_text(Path(out_dir) / "results.md", "\n".join(lines))


def _num(v) -> str:
    return "-" if v is None else f"{v:.3g}"


def _spread(metrics: Mapping[str, float], key: str) -> str:
    if key not in metrics:
        return "-"
    fmt = ".2f" if ("f@" in key or "cpu_s" in key) else ".0f"
    return f"{metrics[key]:{fmt}} [{metrics[key + '_q25']:{fmt}}-{metrics[key + '_q75']:{fmt}}]"


def write_figures(task, datamodule, out_dir: Path, n: int = 4, evaluation: Evaluation | None = None) -> list[Path]:
    """``body_fits.png``: the first ``n`` held-out Anny people, the input and the fits (shaded renders)."""
    if n <= 0:
        return []
    s = _settings(evaluation.artefacts.get("settings", {}) if evaluation and evaluation.artefacts else {})
    return [write_fit_sheet(datamodule.anny_body(), task.regressor(), refine_config(s["refine_global"], s["refine_full"]),
                            n, s, Path(out_dir) / "body_fits.png")]
