"""A small quality DataModule on synthetic shapes for the quality task's tests, and the cheap stand-in for the
renderer's feature table that it names (``data.feature_tables.fn=tests.helpers.quality.fake_features``)."""
from __future__ import annotations

import math

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from datamodules.quality import QualityDataModule

FAKE_FEATURES = "tests.helpers.quality.fake_features"  # data.feature_tables.fn of the quality tests


def fake_features(ref, dist):
    """Cheap stand-in for ``lit3d.features.table.feature_table`` (same naming scheme)."""
    a = trimesh.load(ref, force="mesh", process=False)
    b = trimesh.load(dist, force="mesh", process=False)
    scale = float(np.linalg.norm(np.ptp(a.vertices, axis=0)))
    d_ab = cKDTree(a.vertices).query(b.vertices)[0] / scale
    d_ba = cKDTree(b.vertices).query(a.vertices)[0] / scale
    chamfer = float(d_ab.mean() + d_ba.mean())
    na = a.face_normals[cKDTree(a.triangles_center).query(b.triangles_center)[1]]
    normal_dev = float(1 - np.abs((na * b.face_normals).sum(1)).mean())
    return {"chamfer": chamfer, "hausdorff": float(max(d_ab.max(), d_ba.max())),
            "mse/ceramic_lightbulb/flat": normal_dev, "psnr/ceramic_lightbulb/flat": -10 * math.log10(normal_dev + 1e-9),
            "ms_ssim/ceramic_lightbulb/flat": 1 - 3 * chamfer,
            "mask_ssim/ceramic_lightbulb/flat": 1 - normal_dev - chamfer,
            "faces_ratio": len(b.faces) / len(a.faces)}


def make_dm(tmp_path, **kw) -> QualityDataModule:
    args = dict(data_dir=str(tmp_path / "q"), seed=0,
                synth={"shapes": ["blob", "bumpy", "torus", "rock"], "n_levels": 2,
                       "distortions": ["noise", "taubin", "simplify", "quantize"], "subdivisions": 3},
                feature_tables={"fn": FAKE_FEATURES})
    args.update(kw)
    return QualityDataModule(**args)
