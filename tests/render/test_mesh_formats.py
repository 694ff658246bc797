"""One surface scores 1 whatever its file format.

STL stores every triangle with its own three vertices; read as they are, every vertex normal
is its face's normal and smooth shading turns flat, so ``lit3d-score cow.obj cow.stl`` gave
0.944. STL vertices are now merged on load, as OBJ's are shared.
"""
from __future__ import annotations

import json

import pytest
import trimesh

from lit3d.cli.score import main
from lit3d.render.convert import to_mesh


@pytest.mark.parametrize("fmt", ["stl", "glb", "ply"])
def test_the_same_surface_in_another_format_scores_one(tmp_path, capsys, fmt):
    mesh = trimesh.creation.icosphere(3)
    mesh.export(tmp_path / "s.obj")
    mesh.export(tmp_path / f"s.{fmt}")
    assert main([str(tmp_path / "s.obj"), str(tmp_path / f"s.{fmt}"), "--size", "64", "--styles", "toon,jade",
                 "--json", "--no-cache"]) == 0
    assert json.loads(capsys.readouterr().out)["overall_score"] == pytest.approx(1.0, abs=1e-4)
    loaded = to_mesh(tmp_path / f"s.{fmt}")
    assert len(loaded.vertices) == len(mesh.vertices) and len(loaded.faces) == len(mesh.faces)
