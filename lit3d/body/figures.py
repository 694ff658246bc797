"""The body task's picture: held-out Anny people, their depth image and the body fits, shaded."""
from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from lit3d.body.fit_scores import anny_person, fit, per_vertex_error
from lit3d.body_fit.model import Body
from lit3d.body_fit.synthetic import FLIP, Camera, sensed_depth
from lit3d.body_model.bodies import sample_phenotype
from lit3d.geometry.normalise import bounding_frame
from lit3d.render.shaded import shaded_views
from lit3d.utils.figures import labelled_grid
from lit3d.utils.io import atomic_write_bytes

CELL = 256
VIEW = np.array([[0.0, 0.0, 1.0]])  # towards the input camera, GL frame
COLUMNS = ["input depth", "truth", "regressor alone", "regressor + refinement"]


def depth_tile(depth: np.ndarray, size: int = CELL) -> np.ndarray:
    """``(size, size, 3) uint8``: the person's depth (near bright, background black), cropped to the
    foreground's box, letterboxed."""
    from PIL import Image

    fg = depth > 0
    rows, cols = np.nonzero(fg)
    d = depth[rows.min():rows.max() + 1, cols.min():cols.max() + 1].astype(np.float64)
    f = d > 0
    lo, hi = d[f].min(), d[f].max()
    grey = np.where(f, 0.25 + 0.75 * (hi - d) / max(hi - lo, 1e-9), 0.0)
    img = Image.fromarray((grey * 255).astype(np.uint8))
    k = size / max(img.size)
    img = img.resize((max(1, round(img.width * k)), max(1, round(img.height * k))), Image.BILINEAR)
    canvas = Image.new("L", (size, size))
    canvas.paste(img, ((size - img.width) // 2, (size - img.height) // 2))
    return np.repeat(np.asarray(canvas)[..., None], 3, 2)


def mesh_tile(verts_cam: np.ndarray, faces: np.ndarray, centre: np.ndarray, scale: float) -> np.ndarray:
    """A shaded render ``(CELL, CELL, 3) uint8`` of camera-frame vertices, seen from the input camera,
    in the frame ``centre``/``scale`` (shared by one row's meshes)."""
    import trimesh

    mesh = trimesh.Trimesh((verts_cam * FLIP - centre) * scale, faces, process=False)
    return shaded_views(mesh, VIEW, CELL, "basic_1", 0.6, background=1.0)[0]


def write_fit_sheet(body: Body, regressor, refine, n: int, s: dict, path: Path) -> Path:
    """PNG of the first ``n`` held-out Anny people of the evaluation settings ``s``: input depth | true
    posed body | regressor alone | regressor + refinement (per-vertex median errors in the labels)."""
    cam = Camera.default()
    rows = []
    for i in range(n):
        pheno = sample_phenotype(s["body_seed"], i, "adult", body.model.model)
        truth, _ = anny_person(body, pheno, s["pose_seed"], i, s["poses"])
        depth, _ = sensed_depth(truth, body.faces, cam, np.random.default_rng([s["body_seed"], i, 71]), s["sensor"])
        r = fit(body, depth, cam, f"anny {i}", init=(regressor, refine), alone=False)
        centre, scale = bounding_frame(truth * FLIP)
        errs = {m: 1000 * float(np.median(per_vertex_error(r[m].vertices, truth))) for m in ("init", "refined")}
        rows.append({"label": f"person {i}\nposed error:\n alone {errs['init']:.0f} mm\n refined {errs['refined']:.0f} mm",
                     "cells": [depth_tile(depth), mesh_tile(truth, body.faces, centre, scale),
                               mesh_tile(r["init"].vertices, body.faces, centre, scale),
                               mesh_tile(r["refined"].vertices, body.faces, centre, scale)]})
    grid = labelled_grid(rows, COLUMNS, f"Body fit on held-out Anny people (draw {s['body_seed']}, {s['sensor']} sensor)",
                         cell=CELL, left=170)
    buf = io.BytesIO()
    grid.save(buf, format="PNG")
    return atomic_write_bytes(path, buf.getvalue())
