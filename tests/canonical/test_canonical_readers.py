"""TOSCA and SHREC'14 readers round-trip every format on files the tests write."""

import numpy as np
import pytest
import trimesh

from datamodules.canonical import shrec14, tosca
from datamodules.canonical.tosca import MeshReadError
from tests.helpers.paths import SHARED_DATA

SHARED = SHARED_DATA / "tosca8k"


def _mesh(seed=0):
    m = trimesh.creation.icosphere(subdivisions=1)
    v = m.vertices * (1 + 0.1 * np.random.default_rng(seed).random((len(m.vertices), 1)))
    return v, m.faces.astype(np.int64)


@pytest.mark.parametrize("ext", [".mat", ".vert", ".off", ".ply", ".obj"])
def test_round_trip_each_format(tmp_path, ext):
    v, f = _mesh()
    path = tmp_path / f"cat3{ext}"
    if ext == ".mat":
        tosca.write_mat(path, v, f)
    elif ext == ".vert":
        tosca.write_vert_tri(path, v, f)
    elif ext == ".off":
        tosca.write_off(path, v, f)
    else:
        trimesh.Trimesh(v, f, process=False).export(path)
    v2, f2 = tosca.read_mesh(path)
    np.testing.assert_allclose(v2, v, atol=1e-6)
    np.testing.assert_array_equal(f2, f)


def test_mat_is_one_based_surface_struct(tmp_path):
    from scipy.io import loadmat

    v, f = _mesh()
    tosca.write_mat(tmp_path / "dog0.mat", v, f)
    raw = loadmat(tmp_path / "dog0.mat", squeeze_me=True, struct_as_record=False)["surface"]
    assert raw.TRIV.min() == 1 and raw.X.shape == (len(v),)


def test_off_with_polygons_and_comments(tmp_path):
    p = tmp_path / "wolf1.off"
    p.write_text("OFF # a square\n4 1 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n")
    v, f = tosca.read_off(p)
    assert v.shape == (4, 3) and f.tolist() == [[0, 1, 2], [0, 2, 3]]


def test_index_globs_gaps_and_prefers_mat(tmp_path):
    v, f = _mesh()
    for name in ("dog0", "dog2", "dog5", "horse0", "horse3"):
        tosca.write_off(tmp_path / f"{name}.off", v, f)
    tosca.write_mat(tmp_path / "dog2.mat", v, f)
    (tmp_path / "notes.txt").write_text("x")
    items = tosca.index_tosca(tmp_path)
    assert [(i.cls, i.pose) for i in items] == [("dog", 0), ("dog", 2), ("dog", 5), ("horse", 0), ("horse", 3)]
    assert items[1].path.suffix == ".mat"
    assert tosca.parse_name("david13.off") == ("david", 13)


def test_bad_files_name_the_file_and_problem(tmp_path):
    p = tmp_path / "cat1.off"
    p.write_text("OFF\n3 1 0\n0 0 0\n1 0 0\n")
    with pytest.raises(MeshReadError, match="cat1.off.*truncated"):
        tosca.read_mesh(p)
    q = tmp_path / "cat2.off"
    q.write_text("OFF\n3 1 0\n0 0 0\n1 0 nan\n0 1 0\n3 0 1 2\n")
    with pytest.raises(MeshReadError, match="cat2.off.*NaN"):
        tosca.read_mesh(q)
    (tmp_path / "cat9.stl").write_text("solid")
    with pytest.raises(MeshReadError, match="cat9.stl.*unsupported"):
        tosca.read_mesh(tmp_path / "cat9.stl")
    tosca.write_vert_tri(tmp_path / "cat4.vert", *_mesh())
    (tmp_path / "cat4.tri").unlink()
    with pytest.raises(MeshReadError, match="cat4.vert.*cat4.tri"):
        tosca.read_mesh(tmp_path / "cat4.vert")


def test_shrec14_cla_round_trip_and_index(tmp_path):
    v, f = _mesh()
    classes = {"subject_a": ["0", "1", "2"], "subject_b": ["3", "4"]}
    shrec14.write_cla(tmp_path / "test.cla", classes)
    assert shrec14.read_cla(tmp_path / "test.cla") == classes
    (tmp_path / "Data").mkdir()
    for i in range(5):
        if i % 2:
            tosca.write_off(tmp_path / "Data" / f"{i}.off", v, f)
        else:
            trimesh.Trimesh(v, f, process=False).export(tmp_path / "Data" / f"{i}.obj")
    items = shrec14.index_shrec14(tmp_path)
    assert [(i.subject, i.pose, i.mesh_id) for i in items] == [
        ("subject_a", 0, "0"), ("subject_a", 1, "1"), ("subject_a", 2, "2"), ("subject_b", 0, "3"), ("subject_b", 1, "4")]
    v2, f2 = shrec14.load(items[3])
    np.testing.assert_allclose(v2, v, atol=1e-6)


def test_shrec14_errors(tmp_path):
    (tmp_path / "bad.cla").write_text("PSB 1\n1 3\nA 0 3\n0\n1\n")
    with pytest.raises(MeshReadError, match="lists 2 of 3"):
        shrec14.read_cla(tmp_path / "bad.cla")
    shrec14.write_cla(tmp_path / "bad.cla", {"A": ["7"]})
    with pytest.raises(MeshReadError, match="model '7'.*no mesh file"):
        shrec14.index_shrec14(tmp_path)


@pytest.mark.skipif(not SHARED.is_dir(), reason="../shared/data/tosca8k not present")
def test_real_tosca8k_index():
    items = tosca.index_tosca(SHARED)
    counts = {}
    for it in items:
        counts[it.cls] = counts.get(it.cls, 0) + 1
    assert counts == {"cat": 11, "centaur": 6, "david": 7, "dog": 9, "horse": 8, "michael": 20, "victoria": 12,
                      "wolf": 3}
    v0, f0 = tosca.read_mesh(SHARED / "cat0.ply")
    v3, f3 = tosca.read_mesh(SHARED / "cat3.ply")
    assert v0.shape == v3.shape and (f0 == f3).all()  # shared connectivity
