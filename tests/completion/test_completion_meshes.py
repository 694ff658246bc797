"""Completion data from real CAD models: solid voxels, the three mesh sources, the DataModule."""
from __future__ import annotations

import json
import zipfile
from pathlib import Path

import numpy as np
import pytest
import trimesh

from datamodules.cache import DataError
from datamodules.completion import CompletionDataModule
from datamodules.completion.cad_models import (
    CadModel, category_of, index_mesh_folder, index_shapenet, load_model_mesh, split_models,
)
from datamodules.completion.depth_voxels import ViewGeometry, make_sample, max_pool, target_occupancy
from datamodules.completion.mesh_shapes import MeshShape
from datamodules.completion.meshes import attach_models
from datamodules.completion.sweethome3d import assign_category, credits_markdown, index_sweethome3d
from lit3d.geometry.solid_voxels import solid_voxels, surface_voxels
from lit3d.sensing.placement import camera_rotation

RES = 48


def centres(res: int) -> np.ndarray:
    """(res^3, 3) voxel centres in index coordinates, C order."""
    g = np.arange(res) + 0.5
    return np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)


def iou(a: np.ndarray, b: np.ndarray) -> float:
    return float((a & b).sum() / max((a | b).sum(), 1))


# ---------------------------------------------------------------- solid voxels
def test_closed_sphere_matches_the_analytic_inside_test():
    sphere = trimesh.creation.icosphere(subdivisions=4, radius=18.0)
    v = sphere.vertices + RES / 2
    solid = solid_voxels(v, sphere.faces, RES)
    exact = (np.linalg.norm(centres(RES) - RES / 2, axis=1) <= 18.0).reshape(RES, RES, RES)
    assert solid[exact].all() or solid[exact].mean() > 0.995  # every inside voxel (the shell is conservative)
    assert iou(solid, exact) > 0.85
    assert not solid[0].any() and not solid[:, :, -1].any()


def test_open_box_without_a_bottom_is_still_solid():
    """A flood fill from outside leaks through the missing face; the winding number does not."""
    box = trimesh.creation.box(extents=(30.0, 20.0, 24.0))
    down = box.face_normals[:, 1] < -0.9
    open_box = trimesh.Trimesh(box.vertices + RES / 2, box.faces[~down], process=False)
    assert not open_box.is_watertight
    from scipy import ndimage

    shell = surface_voxels(open_box.vertices, open_box.faces, RES)
    assert ndimage.binary_fill_holes(shell).sum() == shell.sum()  # the naive fill adds nothing
    solid = solid_voxels(open_box.vertices, open_box.faces, RES)
    c = centres(RES).reshape(RES, RES, RES, 3) - RES / 2
    exact = (np.abs(c) <= np.array([15.0, 10.0, 12.0])).all(-1)
    assert iou(solid, exact) > 0.8
    assert solid[RES // 2, RES // 2, RES // 2]


def test_overlapping_parts_make_their_union_and_thin_panels_survive():
    a = trimesh.creation.box(extents=(20.0, 20.0, 20.0))
    b = trimesh.creation.box(extents=(20.0, 20.0, 20.0))
    b.apply_translation((8.0, 0.0, 0.0))
    panel = trimesh.Trimesh([[2, 2, 40], [40, 2, 40], [40, 40, 40]], [[0, 1, 2]])  # one-sided, zero thickness
    both = trimesh.util.concatenate([a, b])
    both.apply_translation((RES / 2 - 4, RES / 2, RES / 2 - 10))
    mesh = trimesh.util.concatenate([both, panel])
    solid = solid_voxels(mesh.vertices, mesh.faces, RES)
    c = centres(RES).reshape(RES, RES, RES, 3)
    lo = np.array([RES / 2 - 14, RES / 2 - 10, RES / 2 - 20])
    hi = np.array([RES / 2 + 14, RES / 2 + 10, RES / 2])
    exact = ((c >= lo) & (c <= hi)).all(-1)
    assert iou(solid[:, :, :38], exact[:, :, :38]) > 0.85
    assert solid[:, :, 40].sum() > 0.3 * 38 * 38 / 2  # the panel's voxels


# ---------------------------------------------------------------- rendering a mesh like a procedural shape
def chair_mesh(seed: int) -> trimesh.Trimesh:
    """A small chair-like mesh: a seat, a back and four legs (several overlapping parts)."""
    rng = np.random.default_rng(seed)
    w, d, h = rng.uniform(0.4, 0.6), rng.uniform(0.4, 0.6), rng.uniform(0.4, 0.5)
    parts = [trimesh.creation.box((w, 0.05, d), trimesh.transformations.translation_matrix((0, h, 0))),
             trimesh.creation.box((w, 0.5, 0.05), trimesh.transformations.translation_matrix((0, h + 0.25, -d / 2)))]
    for sx in (-1, 1):
        for sz in (-1, 1):
            parts.append(trimesh.creation.box((0.04, h, 0.04), trimesh.transformations.translation_matrix(
                (sx * (w / 2 - 0.02), h / 2, sz * (d / 2 - 0.02)))))
    return trimesh.util.concatenate(parts)


def test_direct_mesh_target_equals_the_pooled_256_solid():
    m = chair_mesh(0)
    shape = MeshShape("chair", np.asarray(m.vertices), np.asarray(m.faces))
    view = (72.0, 24.0, 5.0)
    out = make_sample(shape, view, target_res=32, input_factor=4, render_factor=2, sensor="recgan",
                      rng=np.random.default_rng(0))
    big = target_occupancy(shape, ViewGeometry(shape, camera_rotation(*view), 256, 1.0))[::-1]  # recgan mirrors x
    assert iou(max_pool(big, 8), out["target"]) > 0.97
    assert (out["surface"] & out["target"]).sum() > 0.9 * out["surface"].sum()


# ---------------------------------------------------------------- sources
def write_chairs(root: Path, n: int, category_dir: str = "chair") -> None:
    (root / category_dir).mkdir(parents=True, exist_ok=True)
    for i in range(n):
        chair_mesh(i).export(root / category_dir / f"chair_{i:02d}.obj")


def test_mesh_folder_index_and_errors(tmp_path):
    write_chairs(tmp_path, 2)
    parts = tmp_path / "sofas" / "big_sofa"
    parts.mkdir(parents=True)
    trimesh.creation.box((2.0, 0.5, 1.0)).export(parts / "base.ply")
    trimesh.creation.box((2.0, 0.6, 0.2)).export(parts / "back.stl")
    (tmp_path / "lamps").mkdir()
    trimesh.creation.box().export(tmp_path / "lamps" / "lamp.obj")
    models, dropped = index_mesh_folder(tmp_path)
    # every category folder is read: "lamps" is a user category of that name
    assert sorted(m.model_id for m in models) == ["chair/chair_00", "chair/chair_01", "couch/big_sofa", "lamps/lamp"]
    sofa = next(m for m in models if m.category == "couch")
    assert len(sofa.files) == 2 and len(load_model_mesh(sofa).faces) == 24  # two parts, one soup
    assert not any("lamps" in d["path"] for d in dropped)
    assert category_of("Airplanes") == "plane" and category_of("display") == "monitor" and category_of("lamp") is None
    bad = tmp_path / "chair" / "broken.off"
    bad.write_text("OFF\n3 1 0\n0 0 0\n1 0\n")
    broken = next(m for m in index_mesh_folder(tmp_path)[0] if m.model_id == "chair/broken")
    with pytest.raises(DataError, match="broken.off"):
        load_model_mesh(broken)
    with pytest.raises(DataError, match="no models found"):
        index_mesh_folder(tmp_path / "lamps")
    with pytest.raises(DataError, match="folder not found"):
        index_mesh_folder(tmp_path / "missing")


def test_shapenet_v1_and_v2_layouts(tmp_path):
    box = trimesh.creation.box()
    (tmp_path / "03001627" / "abc").mkdir(parents=True)
    box.export(tmp_path / "03001627" / "abc" / "model.obj")  # v1
    (tmp_path / "04379243" / "def" / "models").mkdir(parents=True)
    box.export(tmp_path / "04379243" / "def" / "models" / "model_normalized.obj")  # v2
    (tmp_path / "04090263" / "gun1" / "models").mkdir(parents=True)
    box.export(tmp_path / "04090263" / "gun1" / "models" / "model_normalized.obj")
    (tmp_path / "02747177" / "bin1").mkdir(parents=True)  # trash bins: not a thesis category
    (tmp_path / "03001627" / "empty").mkdir()
    models, dropped = index_shapenet(tmp_path)
    assert {(m.model_id, m.category) for m in models} == {
        ("03001627/abc", "chair"), ("04379243/def", "table"), ("04090263/gun1", "firearm")}
    reasons = {Path(d["path"]).name: d["reason"] for d in dropped}
    assert "not among" in reasons["02747177"] and "model.obj" in reasons["empty"]


def write_catalogue(path: Path, licence: str = "Creative Commons Attribution 3.0 license") -> None:
    """A tiny .sh3f zip: four entries, one duplicate OBJ, one unknown category."""
    chair = chair_mesh(1).export(file_type="obj")
    table = trimesh.creation.box((1.2, 0.7, 0.8)).export(file_type="obj")
    props = [f"license={licence}", "name=Test catalogue", ""]
    entries = [("Chair", "Living room", "Seat", "c/chair.obj", "Ann"),
               ("Oak table", "Living room", "", "c/table.obj", "Bob"),
               ("Chair", "Office", "Seat", "c/chair_copy.obj", "Ann"),
               ("Table lamp", "Lights", "", "c/lamp.obj", "Cy"),
               ("Workbench", "Miscellaneous", "Table", "c/table2.obj", "Di")]
    for n, (name, cat, tags, model, creator) in enumerate(entries, 1):
        props += [f"id#{n}=t#{n}", f"name#{n}={name}", f"category#{n}={cat}", f"tags#{n}={tags}",
                  f"model#{n}=/{model}", f"creator#{n}={creator}", f"width#{n}=50", f"depth#{n}=40", f"height#{n}=80"]
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("PluginFurnitureCatalog.properties", "\n".join(props))
        for member, data in (("c/chair.obj", chair), ("c/chair_copy.obj", chair), ("c/table.obj", table),
                             ("c/lamp.obj", table), ("c/table2.obj", table + "\n")):
            z.writestr(member, data)


def test_sweethome3d_catalogue_categories_licences_and_credits(tmp_path):
    write_catalogue(tmp_path / "test.sh3f")
    models, dropped = index_sweethome3d(tmp_path)
    assert sorted((m.name, m.category) for m in models) == [("Chair", "chair"), ("Oak table", "table")]
    reasons = {d["name"]: d["reason"] for d in dropped}
    assert "same OBJ" in reasons["Chair"] and "excluded from table" in reasons["Table lamp"]
    assert "Workbench" in reasons  # a workbench is neither a bench nor a table here
    assert all(m.licence.startswith("Creative Commons Attribution") for m in models)
    credits = credits_markdown(models)
    assert "Chair (chair) by Ann" in credits and "Creative Commons Attribution 3.0 license" in credits
    mesh = load_model_mesh(next(m for m in models if m.category == "table"))  # scaled to the catalogue size
    assert np.allclose(mesh.extents, [50, 80, 40])
    assert assign_category("Corner sofa", "Couch, Seat", "Living room")[0] == "couch"
    assert assign_category("Wheelchair", "", "Miscellaneous")[0] is None
    (tmp_path / "bad.sh3f").write_text("not a zip")
    with pytest.raises(DataError, match="bad.sh3f"):
        index_sweethome3d(tmp_path)
    with pytest.raises(DataError, match="apt-get install sweethome3d-furniture"):
        index_sweethome3d(tmp_path / "nothing_here")


def test_model_split_keeps_each_model_in_one_group_and_ignores_order():
    models = [CadModel(f"chair/{i}", "chair", ("x",)) for i in range(20)] + [CadModel("table/0", "table", ("x",))]
    a = split_models(models, {"train": 0.7, "val": 0.1, "test": 0.2}, seed=3)
    b = split_models(models[::-1], {"train": 0.7, "val": 0.1, "test": 0.2}, seed=3)
    assert a == b and len(a) == 21
    counts = {g: sum(1 for k, v in a.items() if v == g and k.startswith("chair")) for g in ("train", "val", "test")}
    assert counts == {"train": 14, "val": 2, "test": 4}
    items = [{"category": "chair", "split": s, "shape_index": i, "name": f"{s}{i}"}
             for s in ("train", "val", "test_same", "test_cross") for i in range(6)]
    out, fallback = attach_models(items, models, ("chair", "table"), {"train": 0.7, "val": 0.1, "test": 0.2}, 3, 8)
    by_split = {}
    for it in out:
        by_split.setdefault(it["split"], set()).add(it["model_id"])
    assert not by_split["train"] & (by_split["test_same"] | by_split["val"])
    assert by_split["test_same"] == by_split["test_cross"]
    assert fallback == {}


def test_procedural_share_mixes_only_training_items_by_a_fixed_draw():
    models = [CadModel(f"chair/{i}", "chair", ("x",)) for i in range(20)]
    items = [{"category": "chair", "split": s, "shape_index": i, "name": f"{s}{i}", "file": f"{s}/{i}.npz"}
             for s in ("train", "val", "test_same") for i in range(400)]
    fractions = {"train": 0.7, "val": 0.1, "test": 0.2}
    mixed, _ = attach_models(items, models, ("chair",), fractions, 3, 8, procedural_share=0.25)
    procedural = [it for it in mixed if it["shape_source"] == "procedural"]
    assert {it["split"] for it in procedural} == {"train"}  # validation and test stay real
    assert 80 <= len(procedural) <= 120  # a quarter of the 400 training items (binomial sd 8.7)
    again, _ = attach_models(items[::-1], models, ("chair",), fractions, 3, 8, procedural_share=0.25)
    assert sorted(it["file"] for it in again if it["shape_source"] == "procedural") == \
        sorted(it["file"] for it in procedural)  # fixed by the item and the seed, not by the order
    plain, _ = attach_models(items, models, ("chair",), fractions, 3, 8)
    assert all(it["shape_source"] == "model" for it in plain)
    assert all(it["shape_source"] == "procedural" for it in attach_models(items, models, ("chair",), fractions, 3, 8,
                                                                           procedural_share=1.0)[0] if it["split"] == "train")


def test_datamodule_on_a_mesh_folder(tmp_path):
    write_chairs(tmp_path / "models", 10)
    (tmp_path / "models" / "chair" / "notes.txt").write_text("ignored")
    sizes = {"train": 16, "val": 4, "test_same": 8, "test_cross": 4, "test_unseen": 2}
    dm = CompletionDataModule(source="meshes", root=str(tmp_path / "models"), data_dir=str(tmp_path / "cache"),
                              target_res=32, input_factor=4, sizes=sizes,
                              categories={"seen": ["chair", "table"], "unseen": ["car"]}, batch_size=4,
                              prepare={"progress": False}, meshes={"min_models": 8})
    dm.prepare_data()
    dm.setup()
    m = json.loads((tmp_path / "cache" / "manifest.json").read_text())
    assert set(m["fallback"]) == {"table", "car"} and m["models_per_category"] == {"chair": 10}
    described = dm.describe()
    assert described["fallback"] == m["fallback"] and described["models_used_per_split"]["train"] >= 1
    chair_items = [it for it in m["items"] if it["category"] == "chair"]
    assert all(it["shape_source"] == "model" for it in chair_items)
    train = {it["model_id"] for it in chair_items if it["split"] == "train"}
    test = {it["model_id"] for it in chair_items if it["split"].startswith("test")}
    assert train and test and not train & test
    batch = next(iter(dm.train_dataloader()))
    assert batch["input"].shape[1:] == (1, 8, 8, 8) and batch["target"].shape[1:] == (1, 32, 32, 32)
    assert batch["target"].sum() > 0
    # the same items rendered in 2 spawned processes (data.prepare.workers): the same files
    CompletionDataModule(source="meshes", root=str(tmp_path / "models"), data_dir=str(tmp_path / "cache2"),
                         target_res=32, input_factor=4, sizes=sizes,
                         categories={"seen": ["chair", "table"], "unseen": ["car"]}, batch_size=4,
                         meshes={"min_models": 8}, prepare={"progress": False, "workers": 2}).prepare_data()
    assert json.loads((tmp_path / "cache2" / "manifest.json").read_text())["manifest_hash"] == m["manifest_hash"]
    # a corrupt model: one error naming the file, or skipped with data.prepare.skip_bad
    (tmp_path / "models" / "chair" / "chair_03.obj").write_text("v 0 0 0\nf 1 2 3\n")
    kw = dict(source="meshes", root=str(tmp_path / "models"), target_res=32, input_factor=4, sizes=sizes,
              categories={"seen": ["chair"], "unseen": ["car"]})
    with pytest.raises(DataError, match="chair_03"):
        CompletionDataModule(data_dir=str(tmp_path / "c2"), prepare={"progress": False}, **kw).prepare_data()
    with pytest.raises(DataError, match="chair_03"):  # the same from a worker process
        CompletionDataModule(data_dir=str(tmp_path / "c4"), prepare={"progress": False, "workers": 2}, **kw).prepare_data()
    dm3 = CompletionDataModule(data_dir=str(tmp_path / "c3"), prepare={"progress": False, "skip_bad": True}, **kw)
    dm3.prepare_data()
    m3 = json.loads((tmp_path / "c3" / "manifest.json").read_text())
    assert m3["skipped"] and not any(it.get("model_id") == "chair/chair_03" for it in m3["items"])


@pytest.mark.skipif(not list(Path("/usr/share/sweethome3d/furniture").glob("*.sh3f")),
                    reason="Sweet Home 3D furniture not installed (apt-get install sweethome3d-furniture)")
def test_installed_sweethome3d_catalogues_give_real_furniture():
    models, dropped = index_sweethome3d()
    counts = {c: sum(m.category == c for m in models) for c in ("chair", "table", "couch")}
    assert counts["chair"] >= 40 and counts["table"] >= 30 and counts["couch"] >= 15
    assert all(m.licence for m in models) and len(dropped) > 100


def test_input_statistics_of_real_models(tmp_path):
    from studies.completion.input_stats import STATS, cad_rows, category_table

    write_chairs(tmp_path, 3)
    rows = cad_rows(32, "ortho", "meshes", str(tmp_path), per_category=2, categories=("chair", "table"))
    assert [r["category"] for r in rows] == ["chair", "chair"]
    assert all(0 < r["fill"] < 0.5 and r["inside"] > 0.9 for r in rows) and set(STATS) <= set(rows[0])
    table = category_table({"real": rows, "other": rows[:1]})
    assert "| chair | fill |" in table and "(2)" in table and "(1)" in table
