"""The body fit's measures on held-out people: Anny people rendered through the evaluation's camera
and sensor, and FAUST scans seen from the front (the figures of ``docs/reconstruct.md``).

Camera: the ``lit3d-reconstruct`` default, the 3D-RecGAN++ pinhole (fov 49.124 degrees across both
sides of a 320x240 image, centred), the person ``DISTANCE`` m in front of it, facing it.

- **Held-out Anny people** (:func:`anny_items`): person ``i`` = phenotype ``i`` of draw ``body_seed``
  (Anny's adult shape distribution) in its own pose ``i`` of draw ``pose_seed``
  (:func:`lit3d.body_model.bodies.sample_pose`, yaw included; ``poses="varied"``:
  :func:`lit3d.body_fit.poses.draw_pose`'s mix), its depth image through the sensor's noise. Measured:
  median per-vertex error (mm) of the canonical body (rest pose, about Anny's origin) against the
  true rest-pose body, the same for the posed body in the camera frame, |phenotype error| per label,
  CPU seconds. Beside: the mean body (phenotype .5, no pose; placed and scaled by the fit's rigid stage).
- **FAUST** (:func:`faust_items`): every ``subject<S>_pose<P>`` mesh scaled so that its subject's pose 0
  stands 1.7 m tall, centred on its box, seen from the front; the posed body against the whole FAUST
  surface: two-sided Chamfer (mean of the two directed mean distances, mm) and F-score at 1% and 2% of
  the height (17 and 34 mm). Beside: the visible input points alone and the mean body.

Methods (a row each): ``fit`` (the optimisation alone from the mean body), ``mean`` (the mean body),
``init`` (the regressor alone) and ``refined`` (the regressor + refinement,
:func:`lit3d.body_fit.regressor.fit_from_regressor`); ``fit`` is skipped with ``alone=False``.
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from datamodules.canonical.posesets import index_faust
from lit3d.body_fit.depth_points import observe
from lit3d.body_fit.fit import FitConfig, fit_best, fit_body
from lit3d.body_fit.model import PHENOTYPES, Params
from lit3d.body_fit.poses import draw_pose
from lit3d.body_fit.regressor import fit_from_regressor, regress
from lit3d.body_fit.results import fit_outputs
from lit3d.body_fit.synthetic import FLIP, Camera, render, sensed_depth
from lit3d.body_model.bodies import sample_phenotype, sample_pose
from lit3d.metrics.mesh import surface_samples
from lit3d.metrics.pointcloud import nearest
from lit3d.metrics.surface import fscores

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
    :data:`lit3d.body_fit.model.PHENOTYPES` order."""
    if not isinstance(fitted, dict):

        fitted = dict(zip(PHENOTYPES, np.asarray(fitted, float).tolist()))
    return {k: abs(float(fitted[k]) - float(v)) for k, v in truth.items()}


# ------------------------------------------------------------------ fits
def fit(body, depth: np.ndarray, cam: Camera, label: str, multi_start: bool = False, init=None,
        alone: bool = True) -> dict:
    """The fit (``alone``: the optimisation alone from the mean body) and the mean-body baseline of one
    depth image, with CPU and wall seconds; ``init``: ``(Regressor, refinement FitConfig)`` adds ``init``
    (the regressor alone) and ``refined``, with ``init_cpu_s`` and ``refined_cpu_s``. ``main``: the
    method the item's outputs (quality flag, canonical depth) come from: ``fit``, else ``refined``."""

    obs = observe(depth, cam, label=label)
    mean = fit_body(body, obs, FitConfig(full_iters=0))
    out = {"obs": obs, "mean": mean, "cpu_s": 0.0, "wall_s": 0.0, "main": "fit" if alone else "refined"}
    if alone:
        c0, t0 = time.process_time(), time.perf_counter()
        out["fit"] = fit_best(body, obs) if multi_start else fit_body(body, obs)
        out.update(cpu_s=time.process_time() - c0, wall_s=time.perf_counter() - t0)
    if init is not None:
        reg, cfg = init
        for name, run in (("init", lambda: regress(body, reg, obs)),
                          ("refined", lambda: fit_from_regressor(body, reg, obs, cfg))):
            c0, t0 = time.process_time(), time.perf_counter()
            out[name] = run()
            out[f"{name}_cpu_s"] = time.process_time() - c0
            if not alone and name == "refined":
                out.update(cpu_s=out["refined_cpu_s"], wall_s=time.perf_counter() - t0)
    elif not alone:
        raise ValueError("fit(alone=False) needs a regressor (init)")
    return out


def methods_in(r: dict) -> list[str]:
    return [m for m in METHODS if m in r]


def anny_person(body, pheno: dict, pose_seed: int, i: int, poses: str = "upright") -> tuple[np.ndarray, np.ndarray]:
    """Person ``i``'s camera-frame posed vertices ``(V, 3)`` (centre ``DISTANCE`` m ahead) and y-up
    rest-pose vertices ``(V, 3)`` for phenotype ``pheno``, in pose ``i`` of draw ``pose_seed`` under the
    mix ``poses`` (``upright``: :func:`sample_pose` through the data source's body model;
    otherwise :func:`lit3d.body_fit.poses.draw_pose`, placed by :meth:`lit3d.body_fit.model.Body.place`)."""
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
               rows: list | None = None, multi_start: bool = False, init=None, poses: str = "upright",
               alone: bool = True) -> list[dict]:
    """Fit ``n`` held-out Anny people (module doc; poses of the mix ``poses``, :func:`anny_person`);
    one dict of measures per person, appended to ``rows``."""

    rows = [] if rows is None else rows
    for i in range(n):
        pheno = sample_phenotype(body_seed, i, "adult", body.model.model)
        truth, rest_y = anny_person(body, pheno, pose_seed, i, poses)
        depth, noise = sensed_depth(truth, body.faces, cam, np.random.default_rng([body_seed, i, 71]), sensor)
        r = fit(body, depth, cam, f"anny {i}", multi_start, init, alone)
        row = {"item": i, "phenotype": pheno, "noise": noise, "cpu_s": r["cpu_s"], "wall_s": r["wall_s"],
               "points": len(r["obs"].points)}
        for name in methods_in(r):
            f = r[name]
            row[name] = {"canonical_mm": 1000 * float(np.median(per_vertex_error(body.rest_y_up(f.params), rest_y))),
                         "posed_mm": 1000 * float(np.median(per_vertex_error(f.vertices, truth))),
                         "phenotype_abs": phenotype_error(f.params.phenotype.numpy(), pheno),
                         "cpu_s": r.get(f"{name}_cpu_s", r["cpu_s"] if name == "fit" else None)}
        rows.append(row)
        extra = "".join(f"; {m}: canonical {row[m]['canonical_mm']:.0f} mm, posed {row[m]['posed_mm']:.0f} mm, "
                        f"{row[m]['cpu_s']:.2f} s CPU" for m in ("init", "refined") if m in row)
        main = row[r["main"]]
        say(f"anny {i}: canonical {main['canonical_mm']:.0f} mm (mean body {row['mean']['canonical_mm']:.0f}), "
            f"posed {main['posed_mm']:.0f} mm, {row['cpu_s']:.1f} s CPU{extra}")
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
                init=None, alone: bool = True) -> list[dict]:
    """Fit every FAUST mesh seen from the front (module doc), pose by pose (every subject of pose 0,
    then of pose 1...), from the ``first``-th, at most ``limit`` (0: all); one dict of measures per mesh,
    appended to ``rows``; ``init``: as :func:`fit` (the refined fits' canonical depth images go to
    ``canon_dir`` + ``_refined``)."""

    taus = (0.01 * FAUST_HEIGHT, 0.02 * FAUST_HEIGHT)
    rows = [] if rows is None else rows
    meshes = faust_meshes(root)[first:]
    for stem, verts, faces in meshes[:limit] if limit else meshes:
        depth = render(verts, faces, cam)
        r = fit(body, depth, cam, stem, multi_start, init, alone)
        truth = surface_points(verts, faces, samples)
        out = fit_outputs(body, r[r["main"]], r["obs"])
        if canon_dir is not None:
            canon_dir.mkdir(parents=True, exist_ok=True)
            np.save(canon_dir / f"{stem}_body_canonical_depth.npy", out.canonical_depth)
        row = {"item": stem, "cpu_s": r["cpu_s"], "wall_s": r["wall_s"], "points": len(r["obs"].points),
               "poor_fit": out.quality["poor_fit"], "silhouette_iou": out.quality["silhouette_iou"]}
        sets = {m: surface_points(r[m].vertices, body.faces, samples, 1) for m in methods_in(r)}
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
        main = row[r["main"]]
        say(f"{stem}: Chamfer {main['chamfer']:.0f} mm (points {row['points']['chamfer']:.0f}, mean body "
            f"{row['mean']['chamfer']:.0f}), F@2% {main['f@0.034']:.2f}, {row['cpu_s']:.1f} s CPU{extra}")
    return rows
