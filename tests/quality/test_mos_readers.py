"""MOS dataset readers on small files written here in the published layouts (good and bad)."""
from __future__ import annotations

import csv

import pytest

from datamodules.quality.mos import MosDataError, read_guo2016, read_liris_epfl, read_liris_masking
from tests.helpers.files import liris_epfl, write_box_mesh, write_xlsx








def test_liris_epfl_reads_pairs(tmp_path):
    ds = read_liris_epfl(liris_epfl(tmp_path))
    assert len(ds.items) == 8 and ds.shapes == ["armadillo", "dyno", "rockerarm", "venus"]
    it = ds.items[1]
    assert it.reference.name == "Armadillo.obj" and it.distorted.name == "Armadillo_noise_2.obj" and it.score == 5.0
    assert ds.score_range() == (0.0, 10.0) and not ds.layout.higher_is_better


def test_missing_mesh_names_the_row(tmp_path):
    liris_epfl(tmp_path, missing={"Dyno_noise_2"})
    with pytest.raises(MosDataError, match=r"row \d+ \('Dyno_noise_2'\): no mesh file"):
        read_liris_epfl(tmp_path)
    with pytest.warns(UserWarning, match="Dyno_noise_2"):
        ds = read_liris_epfl(tmp_path, on_error="skip")
    assert len(ds.items) == 7 and len(ds.skipped) == 1


def test_unmatched_row_and_missing_column_and_range(tmp_path):
    root = liris_epfl(tmp_path / "a", rows=[("Model", "MOS"), ("Armadillo_noise_1", 3), ("Bunny_noise_1", 2)])
    write_box_mesh(root / "extra" / "Bunny_noise_1.obj")
    with pytest.raises(MosDataError, match="Bunny_noise_1.*matches no shape of liris_epfl"):
        read_liris_epfl(root)
    root = liris_epfl(tmp_path / "b", rows=[("Model", "Rating"), ("Armadillo_noise_1", 3)])
    with pytest.raises(MosDataError, match="no sheet has both a model-name column"):
        read_liris_epfl(root)
    root = liris_epfl(tmp_path / "c", rows=[("Model", "MOS"), ("Armadillo_noise_1", 11.5)])
    with pytest.raises(MosDataError, match=r"score 11.5 outside the published range 0.0..10.0"):
        read_liris_epfl(root)
    root = liris_epfl(tmp_path / "d", rows=[("Model", "MOS"), ("Armadillo_noise_1", "n/a")])
    with pytest.raises(MosDataError, match="is not a number"):
        read_liris_epfl(root)


def test_no_reference_and_no_spreadsheet(tmp_path):
    root = liris_epfl(tmp_path / "a")
    (root / "Venus" / "Venus.obj").unlink()
    with pytest.raises(MosDataError, match="no reference mesh for shape 'venus'"):
        read_liris_epfl(root)
    (tmp_path / "b" / "Dyno").mkdir(parents=True)
    write_box_mesh(tmp_path / "b" / "Dyno" / "Dyno.obj")
    with pytest.raises(MosDataError, match="no score spreadsheet"):
        read_liris_epfl(tmp_path / "b")
    with pytest.raises(MosDataError, match="dataset root not found"):
        read_liris_epfl(tmp_path / "nowhere")


def test_liris_masking_flat_layout_with_shape_column(tmp_path):
    # flat folder, reference marked "_ref", a shape column, MOS 0..4 with 4 = identical
    for s in ("Armadillo", "Dyno", "Lion", "Bimba"):
        write_box_mesh(tmp_path / "models" / f"{s}_ref.ply")
        for k in range(1, 4):
            write_box_mesh(tmp_path / "models" / f"{s}-noise-rough-{k}.ply")
    rows = [("Object", "Distorted model", "MOS")] + [(s, f"{s}-noise-rough-{k}", 4 - k)
                                                      for s in ("Armadillo", "Dyno", "Lion", "Bimba") for k in range(1, 4)]
    write_xlsx(tmp_path / "masking_mos.xlsx", rows, title_rows=())
    ds = read_liris_masking(tmp_path)
    assert len(ds.items) == 12 and ds.layout.higher_is_better
    assert ds.items[0].reference.name == "Armadillo_ref.ply"
    assert ds.score_range() == (0.0, 4.0)


def test_guo2016_csv_and_data_range(tmp_path):
    shapes = ("dwarf", "hulk", "squirrel", "statue")
    for s in shapes:
        write_box_mesh(tmp_path / s / f"{s}.obj")
        for k in ("noise_1", "taubin_1"):
            write_box_mesh(tmp_path / s / f"{s}_{k}.obj")
    with open(tmp_path / "guo_scores.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["stimulus", "score"])
        for i, s in enumerate(shapes):
            w.writerow([f"{s}_noise_1.obj", 1 + i])
            w.writerow([f"{s}_taubin_1.obj", 2 + i])
    ds = read_guo2016(tmp_path)
    assert len(ds.items) == 8 and ds.score_range() == (1.0, 5.0)
