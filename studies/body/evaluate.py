"""Measure the Anny body fit: held-out Anny people and FAUST, with baselines.

    python -m studies.body.evaluate --out DIR [--anny N] [--faust ../shared/data/faust_a] [--multi-start]

Camera: the ``lit3d-reconstruct`` default, the 3D-RecGAN++ pinhole (fov 49.124 degrees across both
sides of a 320x240 image, centred), the person 3.2 m in front of it, facing it.

- **Held-out Anny people** (``--anny N``): subject ``i`` = phenotype ``i`` of draw ``--body-seed``
  (Anny's adult shape distribution, as ``conf/data/anny.yaml``) in its own pose ``i`` of draw
  ``--pose-seed`` (:func:`lit3d.body_model.bodies.sample_pose`, yaw included; ``--poses varied``:
  :func:`lit3d.body.poses.draw_pose`'s mix, people also lying, folded and upside down); training
  draws use seed 0 (the regressor's 7), these 1000+. The depth image gets the ``recgan`` sensor's noise
  (:data:`lit3d.sensing.sensor.SENSORS`), whose figures are in voxels of a 256 grid: one voxel
  is taken as the person's longest side / 256 (~6.6 mm): misregistration (the body rendered
  shifted by U(-0.75, 0.75) voxels per axis against its truth), range noise (sd 0.25 voxel) and
  15% holes in blobs of 8 voxels (:func:`lit3d.sensing.sensor.hole_mask`, blob size converted
  to pixels at the body's depth). Measured: median per-vertex error (mm) of the canonical body
  (rest pose, fitted phenotype and scale, about Anny's origin) against the true rest-pose body,
  the same for the posed body in the camera frame, mean abs phenotype error per label, fit CPU
  seconds. Beside: the mean body (phenotype .5, no pose; placed and scaled by the fit's rigid stage).
- **FAUST** (``--faust DIR``): every ``subject<S>_pose<P>`` mesh scaled so that its subject's pose 0
  stands 1.7 m tall (y extent), centred on its bounding box, seen from the front; the fitted posed
  body against the whole FAUST surface (its back included): two-sided Chamfer (mean of the two
  directed mean distances, mm) and F-score at 1% and 2% of the height (17 and 34 mm), on
  ``--samples`` area-uniform surface samples of each mesh. Beside: the visible input points alone
  (as the predicted set) and the mean body. The canonical depth images (``<stem>_body_canonical_depth.npy``,
  :func:`lit3d.body.results.canonical_depth`) go to ``DIR/faust_canonical`` for the retrieval
  row (``lit3d-summary --pooled --depth-row body_fit=DIR/faust_canonical ...``).

``--multi-start``: :func:`lit3d.body.fit.fit_best` (four starts probed, the lowest loss goes on) in
place of the single fit from the mean body; CPU seconds count every start.

``--init CKPT`` (a :mod:`lit3d.body.regressor` checkpoint): two more rows beside the optimisation
alone: the regressor alone (its parameters, no step) and the regressor + refinement
(:func:`lit3d.body.regressor.fit_from_regressor`, ``--refine-global`` + ``--refine-full`` steps),
each with its CPU seconds (the crop and network included).

Writes ``DIR/body_eval.json`` (every item) and ``DIR/body_eval.md`` (medians, quartiles), both
rewritten after every item (a stopped run keeps what it measured).
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from lit3d.body_model.bodies import sample_phenotype, sample_pose
from datamodules.canonical.posesets import index_faust
from lit3d.body.fit import FitConfig, fit_best, fit_body
from lit3d.body.model import PHENOTYPES, Body, Params
from lit3d.body.depth_points import observe
from lit3d.body.poses import POSE_MIXES, draw_pose
from lit3d.body.regressor import REFINE_FULL_ITERS, REFINE_GLOBAL_ITERS, fit_from_regressor, load_regressor, \
    refine_config, regress
from lit3d.body.results import fit_outputs
from lit3d.body.synthetic import FLIP, HEIGHT, WIDTH, Camera, render, sensed_depth
from lit3d.metrics.mesh import surface_samples
from lit3d.metrics.pointcloud import nearest
from lit3d.metrics.surface import fscores
from lit3d.sensing.sensor import SENSORS

DISTANCE = 3.2        # metres from the camera to the person's centre
FAUST_HEIGHT = 1.7    # metres: each FAUST subject's pose-0 standing height
METHODS = ("fit", "mean", "init", "refined")  # optimisation alone, mean body, regressor alone, regressor + refinement


# ------------------------------------------------------------------ metrics
def per_vertex_error(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``(V,)`` distances between corresponding vertices of ``a`` and ``b`` ``(V, 3)``."""
    return np.linalg.norm(np.asarray(a, np.float64) - np.asarray(b, np.float64), axis=1)


def chamfer_fscore(pred: np.ndarray, truth: np.ndarray, thresholds) -> dict:
    """Point sets ``pred`` ``(N, 3)`` and ``truth`` ``(M, 3)``: ``chamfer`` = (mean pred->truth +
    mean truth->pred nearest distance) / 2, both directed means, and per threshold ``t``
    ``f@t`` = 2PR / (P + R) with P the share of pred within ``t`` of truth, R of truth within ``t`` of pred."""
    d_pt, d_tp = nearest(pred, truth)[0], nearest(truth, pred)[0]
    out = {"chamfer": float((d_pt.mean() + d_tp.mean()) / 2), "pred_to_truth": float(d_pt.mean()),
           "truth_to_pred": float(d_tp.mean())}
    for t, p, r, f in zip(thresholds, *fscores(d_pt, d_tp, np.asarray(thresholds, dtype=np.float64))):
        out[f"f@{t:g}"], out[f"precision@{t:g}"], out[f"recall@{t:g}"] = float(f), float(p), float(r)
    return out


def in_mm(scores: dict) -> dict:
    """:func:`chamfer_fscore`'s scores with its distances (metres) in millimetres."""
    return {k: 1000 * v if k in ("chamfer", "pred_to_truth", "truth_to_pred") else v for k, v in scores.items()}


def surface_points(verts: np.ndarray, faces: np.ndarray, n: int, seed: int = 0) -> np.ndarray:
    """``(n, 3)`` points uniform by area on the mesh (seeded)."""
    import trimesh

    return surface_samples(trimesh.Trimesh(verts, faces, process=False), n, seed=seed, normalise=False)


def phenotype_error(fitted, truth: dict) -> dict[str, float]:
    """``{label: |fitted - truth|}`` over ``truth``'s labels; ``fitted``: a dict, or an array in
    :data:`lit3d.body.model.PHENOTYPES` order."""
    if not isinstance(fitted, dict):

        fitted = dict(zip(PHENOTYPES, np.asarray(fitted, float).tolist()))
    return {k: abs(float(fitted[k]) - float(v)) for k, v in truth.items()}


# ------------------------------------------------------------------ fits
def fit(body, depth: np.ndarray, cam: Camera, label: str, multi_start: bool = False, init=None) -> dict:
    """The fit and the mean-body baseline of one depth image, with CPU and wall seconds; ``init``:
    ``(Regressor, refinement FitConfig)`` adds ``init`` (the regressor alone) and ``refined``, with
    ``init_cpu_s`` and ``refined_cpu_s``."""

    obs = observe(depth, cam, label=label)
    mean = fit_body(body, obs, FitConfig(full_iters=0))
    c0, t0 = time.process_time(), time.perf_counter()
    res = fit_best(body, obs) if multi_start else fit_body(body, obs)
    out = {"obs": obs, "mean": mean, "fit": res, "cpu_s": time.process_time() - c0, "wall_s": time.perf_counter() - t0}
    if init is not None:
        reg, cfg = init
        for name, run in (("init", lambda: regress(body, reg, obs)),
                          ("refined", lambda: fit_from_regressor(body, reg, obs, cfg))):
            c0 = time.process_time()
            out[name] = run()
            out[f"{name}_cpu_s"] = time.process_time() - c0
    return out


def _methods(r: dict) -> list[str]:
    return [m for m in METHODS if m in r]


def anny_person(body, pheno: dict, pose_seed: int, i: int, poses: str = "upright") -> tuple[np.ndarray, np.ndarray]:
    """Person ``i``'s camera-frame posed vertices ``(V, 3)`` (centre ``DISTANCE`` m ahead) and y-up
    rest-pose vertices ``(V, 3)`` for phenotype ``pheno``, in pose ``i`` of draw ``pose_seed`` under the
    mix ``poses`` (``upright``: :func:`sample_pose` through the data source's body model;
    otherwise :func:`lit3d.body.poses.draw_pose`, placed by :meth:`lit3d.body.model.Body.place`)."""
    if poses == "upright":
        posed_y, rest_y = body.model.vertices(pheno, [sample_pose(pose_seed, i, subject=i), None])
        return posed_y.astype(np.float64) * FLIP + np.array([0.0, 0.0, DISTANCE]), rest_y
    import torch

    theta, rot, _ = draw_pose(pose_seed, i, poses)
    p = Params(torch.tensor([pheno[k] for k in PHENOTYPES], dtype=torch.float32),
               torch.tensor(theta, dtype=torch.float32), torch.tensor(rot, dtype=torch.float32),
               torch.tensor([0.0, 0.0, DISTANCE]), torch.zeros(()))
    with torch.no_grad():
        posed = body.camera_vertices(p).double().numpy()
    return posed, body.model.vertices(pheno, [None])[0]


def anny_items(body, n: int, body_seed: int, pose_seed: int, cam: Camera, sensor: str, say,
               rows: list | None = None, multi_start: bool = False, init=None, poses: str = "upright") -> list[dict]:
    """Fit ``n`` held-out Anny people (module doc; poses of the mix ``poses``, :func:`anny_person`);
    one dict of measures per person, appended to ``rows``."""

    rows = [] if rows is None else rows
    for i in range(n):
        pheno = sample_phenotype(body_seed, i, "adult", body.model.model)
        truth, rest_y = anny_person(body, pheno, pose_seed, i, poses)
        depth, noise = sensed_depth(truth, body.faces, cam, np.random.default_rng([body_seed, i, 71]), sensor)
        r = fit(body, depth, cam, f"anny {i}", multi_start, init)
        row = {"item": i, "phenotype": pheno, "noise": noise, "cpu_s": r["cpu_s"], "wall_s": r["wall_s"],
               "points": len(r["obs"].points)}
        for name in _methods(r):
            f = r[name]
            row[name] = {"canonical_mm": 1000 * float(np.median(per_vertex_error(body.rest_y_up(f.params), rest_y))),
                         "posed_mm": 1000 * float(np.median(per_vertex_error(f.vertices, truth))),
                         "phenotype_abs": phenotype_error(f.params.phenotype.numpy(), pheno),
                         "cpu_s": r.get(f"{name}_cpu_s", r["cpu_s"] if name == "fit" else None)}
        rows.append(row)
        extra = "".join(f"; {m}: canonical {row[m]['canonical_mm']:.0f} mm, posed {row[m]['posed_mm']:.0f} mm, "
                        f"{row[m]['cpu_s']:.2f} s CPU" for m in ("init", "refined") if m in row)
        say(f"anny {i}: canonical {row['fit']['canonical_mm']:.0f} mm (mean body {row['mean']['canonical_mm']:.0f}), "
            f"posed {row['fit']['posed_mm']:.0f} mm, {row['cpu_s']:.1f} s CPU{extra}")
    return rows


def faust_meshes(root: Path) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """``[(stem, camera-frame verts, faces)]`` of every ``subject<S>_pose<P>`` mesh (module doc)."""
    import trimesh


    index = index_faust(root)
    raw = {k: trimesh.load(p, process=False, force="mesh") for k, p in sorted(index.items(), key=lambda kv: (kv[0][1], kv[0][0]))}
    out = []
    for (subject, pose), m in raw.items():
        ref = raw.get((subject, 0), m)
        scale = FAUST_HEIGHT / float(np.ptp(np.asarray(ref.vertices)[:, 1]))
        out.append((f"{subject}_pose{pose}", camera_frame(m.vertices, scale), np.asarray(m.faces)))
    return out


def camera_frame(verts: np.ndarray, scale: float) -> np.ndarray:
    """``(V, 3)`` y-up vertices facing +z -> the camera frame (y down, z forward): scaled, centred on
    their box, the centre ``DISTANCE`` m ahead, facing the camera."""
    v = np.asarray(verts, np.float64) * scale
    v -= (v.min(0) + v.max(0)) / 2
    return v * FLIP + np.array([0.0, 0.0, DISTANCE])


def faust_items(body, root: Path, cam: Camera, samples: int, canon_dir: Path | None, say,
                limit: int = 0, rows: list | None = None, multi_start: bool = False, first: int = 0,
                init=None) -> list[dict]:
    """Fit every FAUST mesh seen from the front (module doc), pose by pose (every subject of pose 0,
    then of pose 1...), from the ``first``-th, at most ``limit`` (0: all); one dict of measures per mesh,
    appended to ``rows``; ``init``: as :func:`fit` (the refined fits' canonical depth images go to
    ``canon_dir`` + ``_refined``)."""

    taus = (0.01 * FAUST_HEIGHT, 0.02 * FAUST_HEIGHT)
    rows = [] if rows is None else rows
    meshes = faust_meshes(root)[first:]
    for stem, verts, faces in meshes[:limit] if limit else meshes:
        depth = render(verts, faces, cam)
        r = fit(body, depth, cam, stem, multi_start, init)
        truth = surface_points(verts, faces, samples)
        out = fit_outputs(body, r["fit"], r["obs"])
        if canon_dir is not None:
            canon_dir.mkdir(parents=True, exist_ok=True)
            np.save(canon_dir / f"{stem}_body_canonical_depth.npy", out.canonical_depth)
        row = {"item": stem, "cpu_s": r["cpu_s"], "wall_s": r["wall_s"], "points": len(r["obs"].points),
               "poor_fit": out.quality["poor_fit"], "silhouette_iou": out.quality["silhouette_iou"]}
        sets = {m: surface_points(r[m].vertices, body.faces, samples, 1) for m in _methods(r)}
        for name, pts in (*sets.items(), ("points", r["obs"].points)):
            row[name] = in_mm(chamfer_fscore(pts, truth, taus))
        for m in ("init", "refined"):
            if m in r:
                q = fit_outputs(body, r[m], r["obs"])
                row[m].update(cpu_s=r[f"{m}_cpu_s"], poor_fit=q.quality["poor_fit"])
                if canon_dir is not None and m == "refined":
                    (canon_dir.parent / f"{canon_dir.name}_refined").mkdir(parents=True, exist_ok=True)
                    np.save(canon_dir.parent / f"{canon_dir.name}_refined" / f"{stem}_body_canonical_depth.npy",
                            q.canonical_depth)
        rows.append(row)
        extra = "".join(f"; {m}: Chamfer {row[m]['chamfer']:.0f} mm, F@2% {row[m]['f@0.034']:.2f}, "
                        f"{row[m]['cpu_s']:.2f} s CPU" for m in ("init", "refined") if m in row)
        say(f"{stem}: Chamfer {row['fit']['chamfer']:.0f} mm (points {row['points']['chamfer']:.0f}, mean body "
            f"{row['mean']['chamfer']:.0f}), F@2% {row['fit']['f@0.034']:.2f}, {row['cpu_s']:.1f} s CPU{extra}")
    return rows


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
                       for m in _methods(anny[0])}
        out["anny"]["cpu_s"] = spread([r["cpu_s"] for r in anny])
    if faust:
        keys = ("chamfer", "f@0.017", "f@0.034", "pred_to_truth", "truth_to_pred")
        out["faust"] = {m: {k: spread([r[m][k] for r in faust]) for k in keys} for m in (*_methods(faust[0]), "points")}
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


def main(argv: list[str] | None = None) -> None:
    import sys

    import torch

    ap = argparse.ArgumentParser(prog="python -m studies.body.evaluate", description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, required=True, help="folder for body_eval.json and body_eval.md")
    ap.add_argument("--anny", type=int, default=20, help="held-out Anny people (0: none)")
    ap.add_argument("--body-seed", type=int, default=1000, help="phenotype draw (training uses 0)")
    ap.add_argument("--pose-seed", type=int, default=1000, help="pose draw (training uses 0)")
    ap.add_argument("--poses", default="upright", choices=sorted(POSE_MIXES),
                    help="pose mix of the Anny people (lit3d.body.poses): upright as the data source, or varied")
    ap.add_argument("--sensor", default="recgan", choices=sorted(SENSORS), help="noise model of the Anny depth images")
    ap.add_argument("--faust", type=Path, default=None, help="FAUST folder (e.g. ../shared/data/faust_a)")
    ap.add_argument("--faust-first", type=int, default=0, help="skip the first K FAUST meshes (pose-major order)")
    ap.add_argument("--faust-limit", type=int, default=0, help="at most K FAUST meshes (0: all)")
    ap.add_argument("--samples", type=int, default=20000, help="surface samples per mesh for Chamfer/F-score")
    ap.add_argument("--multi-start", action="store_true",
                    help="fit from 4 starts (mean body, yaw -/+0.4 rad, arms lowered; lit3d.body.fit.fit_best)")
    ap.add_argument("--init", type=Path, default=None, help="body regressor checkpoint (studies.body.train_regressor): "
                    "adds the rows 'regressor alone' and 'regressor + refinement'")
    ap.add_argument("--refine-global", type=int, default=REFINE_GLOBAL_ITERS, help="rigid steps of the refinement")
    ap.add_argument("--refine-full", type=int, default=REFINE_FULL_ITERS, help="full steps of the refinement")
    ap.add_argument("--refine-poor", type=int, default=0,
                    help="full steps more where the refinement is flagged poor (0: none)")
    ap.add_argument("--threads", type=int, default=1, help="torch CPU threads")
    args = ap.parse_args(argv)
    torch.set_num_threads(args.threads)

    def say(line):
        print(line, file=sys.stderr, flush=True)

    init = None if args.init is None else (load_regressor(args.init),
                                           refine_config(args.refine_global, args.refine_full,
                                                         poor_extra_iters=args.refine_poor))
    cam, body = Camera.default(), Body()
    args.out.mkdir(parents=True, exist_ok=True)
    meta = {"command": "python -m studies.body.evaluate " + " ".join(argv if argv is not None else sys.argv[1:]),
            "body_seed": args.body_seed, "pose_seed": args.pose_seed, "poses": args.poses, "sensor": args.sensor,
            "starts": "4 starts, best probe kept" if args.multi_start else "one start: the mean body",
            "camera": {**cam.__dict__, "width": WIDTH, "height": HEIGHT, "distance_m": DISTANCE}, "threads": args.threads}
    if init is not None:
        meta.update(init=str(args.init), refine=f"{args.refine_global} + {args.refine_full} steps"
                    + (f", {args.refine_poor} more where flagged poor" if args.refine_poor else ""))
    anny: list[dict] = []
    faust: list[dict] = []

    def write() -> str:  # after every item: a stopped run keeps what it measured
        summary = summarise(anny, faust)
        (args.out / "body_eval.json").write_text(json.dumps({"meta": meta, "summary": summary, "anny": anny,
                                                            "faust": faust}, indent=1), "utf-8")
        text = markdown(summary, meta)
        (args.out / "body_eval.md").write_text(text, "utf-8")
        return text

    def note(line):
        say(line)
        write()

    if args.anny:
        anny_items(body, args.anny, args.body_seed, args.pose_seed, cam, args.sensor, note, anny, args.multi_start, init,
                   args.poses)
    if args.faust is not None:
        faust_items(body, args.faust, cam, args.samples, args.out / "faust_canonical", note,
                    args.faust_limit, faust, args.multi_start, args.faust_first, init)
    print(write())


if __name__ == "__main__":
    main()
