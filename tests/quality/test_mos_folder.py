"""A human-rated set of your own (``data=mos_folder``): the reader, its one-line errors, and
``lit3d-data`` / ``lit3d-train`` on a 2-shape, 8-stimulus set written here."""
from __future__ import annotations

import csv
import json
import sys

import numpy as np
import pytest
import trimesh

from datamodules.quality.mos import MosDataError
from datamodules.quality.mos_folder import read_mos_folder

LEVELS = (0.002, 0.006, 0.012, 0.02)
# a cheap feature table: 32 px renders, one style, two image measures (the quality tests' way)
TINY_FEATURES = ["data.feature_tables.options.size=32", "data.feature_tables.options.styles=[ceramic_lightbulb]",
                 "data.feature_tables.options.measures=[mask_ssim,mse]", "data.feature_tables.options.n_samples=500"]


def write_set(root, shape_column: bool = False, rows: list | None = None):
    """DIR/<shape>/<shape>.obj + DIR/<shape>/<shape>_noise<i>.obj (2 shapes x 4 levels) + scores.csv
    (``stimulus, [shape,] mos``; MOS 1..5, higher = better: the noisier, the lower)."""
    shapes = {"ball": trimesh.creation.icosphere(2), "crate": trimesh.creation.box((1.0, 0.6, 0.8)).subdivide().subdivide()}
    out = []
    for name, mesh in shapes.items():
        (root / name).mkdir(parents=True)
        mesh.export(root / name / f"{name}.obj")
        for i, sigma in enumerate(LEVELS):
            noisy = mesh.copy()
            noisy.vertices += np.random.default_rng(i).normal(0, sigma, noisy.vertices.shape)
            noisy.export(root / name / f"{name}_noise{i}.obj")
            out.append((f"{name}_noise{i}", name, round(4.8 - i, 1)))
    with open(root / "scores.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["stimulus", "shape", "mos"] if shape_column else ["stimulus", "mos"])
        for stim, shape, mos in rows if rows is not None else out:
            w.writerow([stim, shape, mos] if shape_column else [stim, mos])
    return root


def test_reader_takes_shapes_from_folders_or_the_shape_column(tmp_path):
    ds = read_mos_folder(write_set(tmp_path / "a"), score_range=(1, 5), higher_is_better=True)
    assert ds.shapes == ["ball", "crate"] and len(ds.items) == 8 and ds.unrated == []
    assert ds.items[0].reference.name == "ball.obj" and ds.layout.higher_is_better
    assert ds.score_range() == (1, 5)
    ds = read_mos_folder(write_set(tmp_path / "b", shape_column=True), higher_is_better=False)
    assert ds.shapes == ["ball", "crate"] and ds.score_range() == (1.8, 4.8)  # null range: the table's


def test_reader_errors_name_the_file_and_the_problem(tmp_path):
    root = write_set(tmp_path / "a")
    with pytest.raises(MosDataError, match="data.higher_is_better"):
        read_mos_folder(root)
    with pytest.raises(MosDataError, match=r"scores.csv row 2 \('ball_noise0'\): score 4.8 outside"):
        read_mos_folder(root, score_range=(0, 4), higher_is_better=True)
    (root / "ball" / "ball.obj").unlink()
    with pytest.raises(MosDataError, match=r"row 2 .*no reference for shape 'ball'.*ball/ball.<ext>"):
        read_mos_folder(root, higher_is_better=True)
    root = write_set(tmp_path / "b", rows=[("ball_noise0", "", 3), ("cow_7", "", 2)])
    with pytest.raises(MosDataError, match=r"row 3 \('cow_7'\): no file named 'cow_7'"):
        read_mos_folder(root, higher_is_better=True)
    with pytest.warns(UserWarning, match=r"cow_7.*\(skipped\)"):
        ds = read_mos_folder(root, higher_is_better=True, on_error="skip")
    assert len(ds.items) == 1 and len(ds.skipped) == 1 and len(ds.unrated) == 8  # crate: not rated at all
    (root / "scores.csv").write_text("name,rating\nball_noise0,3\n")
    with pytest.raises(MosDataError, match=r"scores.csv: no score column"):
        read_mos_folder(root, higher_is_better=True)


def test_published_reader_points_an_own_set_to_mos_folder(tmp_path):
    from datamodules.quality.mos import read_mos_dataset

    for shape_column in (False, True):
        root = write_set(tmp_path / str(shape_column), shape_column=shape_column)
        with pytest.raises(MosDataError, match="'ball' is not one of its published shapes.*data=mos_folder"):
            read_mos_dataset(root, "liris_epfl", score_range=(1, 5))


def _cli(module: str, prog: str, args: list[str], monkeypatch, capsys) -> str:
    import importlib

    monkeypatch.setattr(sys, "argv", [prog, *args])
    code = 0
    try:
        importlib.import_module(module).main()
    except SystemExit as exc:  # a failed run exits with its status
        code = exc.code
    out = capsys.readouterr()
    assert code in (0, None), out.err[-3000:]
    return out.out


def test_lit3d_data_and_train_on_an_own_set(tmp_path, monkeypatch, capsys):
    root = write_set(tmp_path / "set")
    common = ["experiment=quality_demo", "data=mos_folder", f"data.root={root}", "data.score_range=[1,5]",
              "data.higher_is_better=true", f"paths.data_dir={tmp_path / 'data'}", *TINY_FEATURES]
    out = _cli("lit3d.cli.data", "lit3d-data", [*common, f"hydra.run.dir={tmp_path / 'prep'}"], monkeypatch, capsys)
    info = json.loads(out[out.index("{"):out.rindex("}") + 1])
    assert info["pairs"] == 8 and info["pairs_per_shape"] == {"ball": 4, "crate": 4}
    assert info["dataset"] == "mos_folder" and info["splits"]["test"]["shapes"] == ["crate"]
    run = tmp_path / "run"
    _cli("lit3d.cli.train", "lit3d-train", [*common, f"hydra.run.dir={run}", "trainer.max_epochs=2", "logger=none",
                                            "task.sfs.epochs=2", "task.sfs.max_features=2", "evaluation.cv=false"],
         monkeypatch, capsys)
    assert list(run.rglob("*.ckpt")) and (run / "config.yaml").is_file()
