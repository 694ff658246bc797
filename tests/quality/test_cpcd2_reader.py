"""CPCD2 layout reader (zipped ASCII PLY + mos.csv) and `data=cpcd2` through the quality DataModule."""
from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np
import pytest

from datamodules.quality.cpcd2 import read_cpcd2
from datamodules.quality.mos import MosDataError
from tests.helpers.paths import SHARED_DATA

DATA = SHARED_DATA / "cpcd2_phil"


def cloud(seed: int, noise: float = 0.0, n: int = 1500) -> tuple[np.ndarray, np.ndarray]:
    i = np.arange(n) + 0.5
    phi, theta = np.arccos(1 - 2 * i / n), np.pi * (1 + 5 ** 0.5) * i
    p = 100 * np.stack([np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi), np.cos(phi)], 1)
    c = np.clip(128 + 100 * np.sin(p / 30) + np.random.default_rng(seed).normal(0, noise, p.shape), 0, 255)
    return p, c.astype(int)


def write_cloud(path: Path, p, c) -> None:
    head = ["ply", "format ascii 1.0", f"element vertex {len(p)}", "property float x", "property float y",
            "property float z", "property uchar red", "property uchar green", "property uchar blue", "end_header"]
    body = [f"{a:.3f} {b:.3f} {z:.3f} {r} {g} {bl}" for (a, b, z), (r, g, bl) in zip(p, c)]
    path.parent.mkdir(parents=True, exist_ok=True)
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr(path.stem + ".ply", "\n".join(head + body) + "\n")


def make_layout(root: Path, rows: list[str] | None = None) -> Path:
    write_cloud(root / "Original" / "ball.zip", *cloud(0))
    write_cloud(root / "Database_10" / "ball_N_34.zip", *cloud(0, noise=40))
    write_cloud(root / "Database_10" / "ball_N_36.zip", *cloud(0, noise=8))
    rows = rows if rows is not None else [
        "ball_N_34,GaussianNoise,2.4,Database_10/ball_N_34.zip",
        "ball_N_35,GaussianNoise,3.1,",  # a stimulus this copy does not hold
        "ball_N_36,GaussianNoise,4.0,Database_10/ball_N_36.zip"]
    (root / "mos.csv").write_text("stimulus,codec,mos,file\n" + "\n".join(rows) + "\n")
    return root


def test_reader_items_and_absent_rows(tmp_path):
    ds = read_cpcd2(make_layout(tmp_path))
    assert [i.name for i in ds.items] == ["ball_N_34", "ball_N_36"]
    assert all(i.shape == "ball" and i.reference.name == "ball.zip" for i in ds.items)
    assert [i.score for i in ds.items] == [2.4, 4.0]
    assert len(ds.skipped) == 1 and "ball_N_35" in ds.skipped[0]
    assert ds.layout.higher_is_better and ds.score_range() == (1.0, 5.0)


@pytest.mark.parametrize("rows,expect", [
    (["ball_N_34,GaussianNoise,abc,Database_10/ball_N_34.zip"], "is not a number"),
    (["ball_N_34,GaussianNoise,7.5,Database_10/ball_N_34.zip"], "outside 1..5"),
    (["ball_N_34,GaussianNoise,2.0,Database_10/missing.zip"], "not found"),
    (["cube_N_34,GaussianNoise,2.0,Database_10/ball_N_34.zip"], "no reference cloud 'cube'"),
])
def test_reader_bad_rows_name_the_file(tmp_path, rows, expect):
    make_layout(tmp_path, rows)
    with pytest.raises(MosDataError) as err:
        read_cpcd2(tmp_path)
    assert expect in str(err.value) and "\n" not in str(err.value)


def test_reader_missing_table(tmp_path):
    (tmp_path / "Original").mkdir()
    with pytest.raises(MosDataError, match="mos.csv"):
        read_cpcd2(tmp_path)


def test_datamodule_cpcd2_builds_matrix(tmp_path):
    from datamodules.quality import QualityDataModule

    root = make_layout(tmp_path / "raw")
    dm = QualityDataModule(data_dir=str(tmp_path / "cache"), source="cpcd2", root=str(root),
                           feature_tables={"options": dict(size=48, styles=["ceramic_lightbulb"],
                                                           measures=["mask_ssim", "psnr"])})
    fm = dm.load_matrix()
    assert fm.items == ["ball/ball_N_34", "ball/ball_N_36"]
    assert {"d1_psnr", "y_psnr", "mask_ssim/albedo_rgb/flat", "mask_ssim/ceramic_lightbulb/smooth"} <= set(fm.names)
    col = fm.columns(["mask_ssim/albedo_rgb/flat", "d1_psnr"])
    assert col[0, 0] < col[1, 0] < 1.0  # stronger colour noise, lower colour Mask-SSIM
    assert col[0, 1] == col[1, 1] == 100.0  # same geometry
    assert fm.target[0] > fm.target[1]  # MOS 2.4 is worse than 4.0


@pytest.mark.slow
@pytest.mark.skipif(not (DATA / "mos.csv").is_file(), reason="../shared/data/cpcd2_phil not here")
def test_cpcd2_phil_reads_and_colour_only_stimulus_scores_below_one():
    from lit3d.features.table import FeatureConfig, feature_table
    from lit3d.render.gbuffer import RenderConfig

    ds = read_cpcd2(DATA)
    assert len(ds.items) == 30 and len(ds.skipped) == 6
    item = next(i for i in ds.items if i.name == "phil_N_34")
    cfg = FeatureConfig(render=RenderConfig(size=64), styles=("ceramic_lightbulb",), measures=("mask_ssim",))
    t = feature_table(item.reference, item.distorted, cfg)
    assert t.features["d1_mse"] == 0.0 and t.overall_score() < 1.0
