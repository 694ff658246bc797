"""The AC3D (.ac/.acc) and Quake-2 (.md2) readers on small files that the tests write themselves."""
from __future__ import annotations

import struct
import zipfile

import numpy as np
import pytest

from datamodules.cache import DataError
from datamodules.completion.ac3d import read_ac, read_ac_objects
from datamodules.completion.md2 import read_md2
from tests.helpers.catalogue_files import CUBE_QUADS, TET_T, TET_V, ac_file, ac_object, md2_bytes

CUBE_V = [(x, y, z) for x in (0, 1) for y in (0, 1) for z in (0, 1)]  # index = 4x + 2y + z






def cube_ac(extra: str = "") -> str:
    return ac_file(ac_object("cube", CUBE_V, CUBE_QUADS, extra=extra), data='data 10\nsome\nlines\n')






# ---------------------------------------------------------------- AC3D
def test_cube_ac_reads_as_a_closed_unit_cube(tmp_path):
    path = tmp_path / "cube.ac"
    path.write_text(cube_ac())
    mesh = read_ac(path)
    assert len(mesh.faces) == 12  # 6 quads, fan-triangulated
    np.testing.assert_allclose(mesh.bounds, [[0, 0, 0], [1, 1, 1]])
    mesh.merge_vertices()
    assert mesh.is_watertight
    assert abs(abs(mesh.volume) - 1.0) < 1e-9


def test_ac_rot_and_loc_apply_down_the_tree(tmp_path):
    # parent: loc (10, 0, 0); child: rot = 90 degrees about z as row-vector matrix, loc (0, 5, 0)
    rot = "rot 0 1 0 -1 0 0 0 0 1"  # v @ R: (1, 0, 0) -> (0, 1, 0)
    child = ac_object("child", [(1, 0, 0), (0, 0, 0), (0, 0, 1)], [(0, 1, 2)], extra=f"{rot}\nloc 0 5 0")
    parent = "OBJECT group\nname \"parent\"\nloc 10 0 0\nkids 1\n" + child
    path = tmp_path / "tree.ac"
    path.write_text(ac_file(parent))
    objs = read_ac_objects(path)
    assert [o.path for o in objs] == ["parent/child"]
    np.testing.assert_allclose(objs[0].vertices, [[10, 6, 0], [10, 5, 0], [10, 5, 1]])


def test_acc_triangle_strip_and_dropped_lines(tmp_path):
    strip = [(0, 0, 0), (0, 1, 0), (1, 0, 0), (1, 1, 0), (2, 0, 0), (2, 1, 0)]
    verts = [(*v, 0, 0, 1) for v in strip]  # .acc vertices carry a normal
    obj = ac_object("strip", verts, [(0, 1, 2, 3, 4, 5)], flags="0x14")
    line = ac_object("line", [(0, 0, 0), (5, 5, 5)], [(0, 1)], flags="0x2")
    path = tmp_path / "strip.acc"
    path.write_text(ac_file(obj, line))
    mesh = read_ac(path)
    assert len(mesh.faces) == 4  # 6 strip vertices -> 4 triangles; the line adds none
    normals = mesh.face_normals
    assert np.allclose(normals, normals[0])  # one winding along the strip
    assert mesh.bounds[1, 0] == 2  # the line's (5, 5, 5) is not part of the mesh


@pytest.mark.parametrize("mutate,needle", [
    (lambda t: t[: len(t) // 2], "truncated"),
    (lambda t: t.replace("AC3Db", "PLY", 1), "not an AC3D file"),
    (lambda t: t.replace("refs 4\n0 0 0", "refs 4\n99 0 0", 1), "out of range"),
    (lambda t: t.replace("1 1 1\n", "1 x 1\n", 1), "bad number"),
    (lambda t: t.replace("SURF 0x10", "SURF 0x17", 1), "unknown surface type"),
    (lambda t: t.replace("kids 0", "kids 2") + "OBJECT poly\nnumvert 3\n0 0 0\n", "truncated"),
    (lambda t: t.replace("numsurf 6", "numsurf 6\nbanana"), "expected SURF"),
])
def test_bad_ac_files_name_the_file_and_the_problem(tmp_path, mutate, needle):
    path = tmp_path / "bad.ac"
    path.write_text(mutate(cube_ac()))
    with pytest.raises(DataError, match=needle) as err:
        read_ac(path)
    assert "bad.ac" in str(err.value)


def test_ac_overstated_kids_at_the_end_of_the_file_are_accepted(tmp_path):
    path = tmp_path / "blender.ac"
    path.write_text(cube_ac().replace("kids 1", "kids 3"))  # the world announces 3 kids, the file has 1
    assert len(read_ac(path).faces) == 12


def test_ac_inside_a_zip_and_without_triangles(tmp_path):
    archive = tmp_path / "models.zip"
    with zipfile.ZipFile(archive, "w") as z:
        z.writestr("m/cube.ac", cube_ac())
        z.writestr("m/lines.ac", ac_file(ac_object("l", [(0, 0, 0), (1, 1, 1)], [(0, 1)], flags="0x1")))
    assert len(read_ac(f"{archive}::m/cube.ac").faces) == 12
    with pytest.raises(DataError, match="without triangles"):
        read_ac(f"{archive}::m/lines.ac")
    with pytest.raises(DataError, match="cannot read"):
        read_ac(f"{archive}::m/missing.ac")


# ---------------------------------------------------------------- MD2
def test_md2_tetrahedron_frame0_scaled_and_outward(tmp_path):
    path = tmp_path / "tet.md2"
    path.write_bytes(md2_bytes(TET_V, TET_T, scale=(0.5, 0.5, 0.5), translate=(1, 2, 3), frames=2))
    mesh = read_md2(path)
    np.testing.assert_allclose(mesh.vertices, np.asarray(TET_V) * 0.5 + [1, 2, 3])
    assert len(mesh.faces) == 4 and mesh.is_watertight
    assert mesh.volume > 0  # counter-clockwise: outward normals, positive volume
    np.testing.assert_allclose(mesh.volume, 5.0 ** 3 / 6)


@pytest.mark.parametrize("mutate,needle", [
    (lambda b: b[:40], "shorter than its 68-byte header"),
    (lambda b: b[:-10], "truncated MD2"),
    (lambda b: b"IDP3" + b[4:], "not an MD2 file"),
    (lambda b: b[:4] + struct.pack("<i", 7) + b[8:], "version 7"),
    (lambda b: b[:68] + struct.pack("<H", 200) + b[70:], "uses vertex 200"),
    (lambda b: b[:24] + struct.pack("<i", -1) + b[28:], "bad MD2 counts"),
])
def test_bad_md2_files_name_the_file_and_the_problem(tmp_path, mutate, needle):
    path = tmp_path / "bad.md2"
    path.write_bytes(mutate(md2_bytes(TET_V, TET_T)))
    with pytest.raises(DataError, match=needle) as err:
        read_md2(path)
    assert "bad.md2" in str(err.value)


def test_md2_inside_a_pk3(tmp_path):
    pk3 = tmp_path / "0models.pk3"
    with zipfile.ZipFile(pk3, "w") as z:
        z.writestr("models/weapons/tet/tet.md2", md2_bytes(TET_V, TET_T))
    assert len(read_md2(f"{pk3}::models/weapons/tet/tet.md2").faces) == 4
