"""Catalogue sources (data.source=installed): rules and frames on small trees written here, and every
unpacked package (scripts/bootstrap_extras.sh) that is present; each absent one is skipped by name."""
from __future__ import annotations

import zipfile

import numpy as np
import pytest

from datamodules.cache import DataError
from datamodules.completion.cad_models import load_model_mesh
from datamodules.completion.catalogues import (
    CATALOGUES, catalogue_root, frame, index_installed, index_ufoai, package_tree, present_packages,
)
from tests.helpers.catalogue_files import CUBE_QUADS, TET_T, TET_V, ac_file, ac_object, md2_bytes


def test_frame_turns_source_axes_to_y_up_z_front():
    r = np.asarray(frame("+z", "+x")).reshape(3, 3)
    np.testing.assert_allclose(r @ [0, 0, 1], [0, 1, 0])  # up -> +y
    np.testing.assert_allclose(r @ [1, 0, 0], [0, 0, 1])  # front -> +z
    assert np.isclose(np.linalg.det(r), 1.0)
    np.testing.assert_allclose(np.asarray(frame("+y", "+z")).reshape(3, 3), np.eye(3))


def test_ufoai_rules_join_tyres_and_drop_the_rest(tmp_path):
    pk3 = tmp_path / "0models.pk3"
    tet = md2_bytes(TET_V, TET_T)
    with zipfile.ZipFile(pk3, "w") as z:
        for name in ("weapons/smg/smg", "weapons/smg/smg_clip", "weapons/knife/knife", "objects/cars/van/van1",
                     "objects/cars/van/van1t", "objects/cars/trailer/boxtrailer", "objects/furniture/chairs/chair1"):
            z.writestr(f"models/{name}.md2", tet)
    models, dropped = index_ufoai(pk3)
    got = {m.model_id: m for m in models}
    assert {k: m.category for k, m in got.items()} == {
        "ufoai/weapons/smg/smg": "firearm", "ufoai/objects/cars/van/van1": "car",
        "ufoai/objects/furniture/chairs/chair1": "chair"}
    assert len(got["ufoai/objects/cars/van/van1"].files) == 2  # body + tyres
    assert {d["model"].split("::")[1] for d in dropped} == {
        "models/weapons/smg/smg_clip.md2", "models/weapons/knife/knife.md2", "models/objects/cars/trailer/boxtrailer.md2"}
    assert all(d["reason"] for d in dropped)
    # z-up in the file -> +y up after loading (the tetrahedron's apex (0, 0, 10) goes to y)
    mesh = load_model_mesh(got["ufoai/weapons/smg/smg"])
    assert np.isclose(mesh.vertices[:, 1].max(), 10.0)


def test_installed_trees_under_a_root_and_absent_packages_named(tmp_path, monkeypatch):
    monkeypatch.setenv("LIT3D_CATALOGUES", str(tmp_path))
    assert catalogue_root() == tmp_path
    tree = tmp_path / "crrcsim-data" / CATALOGUES["crrcsim-data"][0]
    (tree / "objects").mkdir(parents=True)
    (tree / "models").mkdir()
    (tree / "objects" / "glider.ac").write_text(ac_file(ac_object("body", [(x, y, z) for x in (0, 1) for y in (0, 1)
                                                                             for z in (0, 1)], CUBE_QUADS)))
    (tree / "objects" / "hut.ac").write_text(ac_file(ac_object("hut", [(0, 0, 0), (1, 0, 0), (0, 1, 0)], [(0, 1, 2)])))
    (tree / "models" / "glider.xml").write_text('<graphics model="glider.ac"/>')
    system_wide = [p for p in CATALOGUES if p != "crrcsim-data" and package_tree(tmp_path, p, CATALOGUES[p][0])]
    assert present_packages() == sorted(["crrcsim-data", *system_wide], key=list(CATALOGUES).index)
    models, dropped = index_installed(packages=["crrcsim-data"])
    assert [(m.model_id, m.category, m.licence) for m in models] == [("crrcsim/glider", "plane", "GPL-2")]
    assert [d["reason"] for d in dropped] == ["scenery (no airplane description names it)"]
    assert len(load_model_mesh(models[0]).faces) == 12
    with pytest.raises(DataError, match="unknown catalogue"):
        index_installed(packages=["nope"])


EXPECTED = {  # package -> categories it must give (at least one model each) when unpacked
    "flightgear-data-ai": {"plane"}, "crrcsim-data": {"plane"}, "ufoai-data": {"firearm", "car", "chair", "table"},
    "sweethome3d": {"chair", "table", "couch", "monitor"}, "minetest-mod-homedecor": {"faucet", "bench", "monitor"},
    "sweethome3d-furniture": {"chair", "table", "couch", "car"},
}


@pytest.mark.parametrize("package", sorted(CATALOGUES))
def test_unpacked_catalogue_indexes_and_its_first_model_loads_upright(package):
    root = catalogue_root()
    if package_tree(root, package, CATALOGUES[package][0]) is None:
        pytest.skip(f"{package} not unpacked in {root} nor installed (scripts/bootstrap_extras.sh unpacks it)")
    models, dropped = index_installed(packages=[package]) if package != "torcs-data" else ([], None)
    if package == "torcs-data":
        with pytest.raises(DataError, match="no catalogue models"):
            index_installed(packages=[package])
        return
    assert EXPECTED[package] <= {m.category for m in models}
    assert len({m.model_id for m in models}) == len(models)
    assert all(m.licence and m.creator for m in models) and all(d["reason"] for d in dropped)
    if package == "ufoai-data":  # each model its own file's licence from ufoai-data's DEP-5 copyright
        assert {m.licence for m in models} >= {"GPL-2", "GPL-2+", "CC-BY-SA-3.0"}, {m.licence for m in models}
    mesh = load_model_mesh(min(models, key=lambda m: m.model_id))
    ext = mesh.extents
    assert len(mesh.faces) > 10 and np.all(np.isfinite(mesh.vertices))
    assert ext[1] <= max(ext[0], ext[2]) * 1.5  # +y up: not lying on its side as a tall thin stick
