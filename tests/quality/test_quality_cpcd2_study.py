"""The CPCD2 evaluation's bookkeeping on hand-made tables (no rendering)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.stats import spearmanr

from datamodules.quality.mos import MosItem
from studies.quality.cpcd2_study import correlation_rows, family, orientation, subsets


def fake(n: int = 12):
    rng = np.random.default_rng(0)
    mos = np.linspace(1, 5, n)
    items, tables = [], []
    for i in range(n):
        geo = i % 3 != 0
        items.append(MosItem("cpcd2", "ball", f"ball_{'G' if geo else 'N'}_{i:02d}", Path("r"), Path("d"), mos[i]))
        tables.append({"mask_ssim/jade/flat": 0.5 + 0.1 * mos[i] + 0.01 * rng.random(),
                       "mask_ssim/albedo_rgb/flat": 0.2 + 0.15 * mos[i],
                       "mse/jade/flat": 1.0 / mos[i], "d1_mse": (5.5 - mos[i]) if geo else 0.0,
                       "d1_psnr": 10 * mos[i] if geo else 100.0, "hausdorff": 5.5 - mos[i] if geo else 0.0})
    return items, tables, mos


def test_orientation_family_and_subsets():
    assert orientation("mse/jade/flat") == -1 and orientation("hausdorff") == -1 and orientation("d1_psnr") == 1
    assert family("phil_G_01") == "G" and family("phil_N_34") == "N"
    items, tables, _ = fake()
    s = subsets(tables)
    assert s["all"].sum() == 12 and s["colour_only"].sum() == 4 and (s["geometry"] ^ s["colour_only"]).all()


def test_correlation_rows_match_scipy():
    items, tables, mos = fake()
    rows = {r["score"]: r for r in correlation_rows(items, tables, top=2)}
    over = np.array([0.5 * (t["mask_ssim/jade/flat"] + t["mask_ssim/albedo_rgb/flat"]) for t in tables])
    assert rows["overall (unlearned)"]["spearman_all"] == pytest.approx(spearmanr(over, mos)[0])
    assert rows["hausdorff"]["spearman_geometry"] == pytest.approx(1.0)  # oriented: lower distance = better
    assert rows["d1_psnr"]["n_colour_only"] == 4
    singles = [r for r in rows.values() if r["kind"].startswith("single")]
    assert len(singles) == 2 and all(r["spearman_all"] > 0.9 for r in singles)
