"""Blended training poses (datamodules.canonical.blends): the vertex mix, the draw, the fold's
training poses as the only endpoints, rendered images in the training split only, and a subject
whose poses do not share one connectivity named as a clear error."""
from pathlib import Path

import numpy as np
import pytest
import trimesh

from datamodules.canonical import CanonicalDataModule, DataError
from datamodules.canonical.blends import BLEND_BASE, add_blends, blend_vertices, draw_blends
from datamodules.canonical import tosca
from tests.helpers.paths import SHARED_DATA

SHARED = SHARED_DATA / "tosca8k"


def test_blend_vertices_mix_linearly_and_refuse_other_connectivity():
    a, b = np.zeros((4, 3)), np.ones((4, 3))
    assert np.allclose(blend_vertices(a, b, 0.25, "x"), 0.25)
    with pytest.raises(DataError, match="cat blend 3.*different vertex counts"):
        blend_vertices(a, np.ones((5, 3)), 0.5, "cat blend 3")


def test_draw_blends_pairs_distinct_endpoints_with_weights_in_range():
    draws = draw_blends(["canonical", 1, 2], 50, np.random.default_rng(0), (0.2, 0.8))
    assert len(draws) == 50 and all(a != b for a, b, _ in draws)
    assert all(0.2 <= t <= 0.8 for _, _, t in draws)
    assert {a for a, _, _ in draws} | {b for _, b, _ in draws} == {"canonical", 1, 2}
    assert draw_blends(["canonical"], 5, np.random.default_rng(0)) == []


def test_add_blends_uses_only_training_poses_as_endpoints():
    """A mesh function that records its calls: held-out poses are never read."""
    read = []

    def mesh(s, p):
        read.append((s, p))
        return np.full((3, 3), 0.0 if p == "canonical" else float(p)), np.zeros((1, 3), int)

    def render(s, v, f):
        return [(np.full((2, 2), v.mean(), np.float32), np.ones((2, 2), bool))]

    cache = {"a": {"depth": {}, "mask": {}}, "b": {"depth": {}, "mask": {}}}
    added = add_blends(cache, [("a", 1), ("a", 2), ("b", 5)], 6, seed=0, fold=1, mesh=mesh, render_views=render)
    assert len(added) == 12 and all(p >= BLEND_BASE for _, p in added)
    assert {p for _, p in read} <= {"canonical", 1, 2, 5}
    # every blended image lies strictly between its endpoints' values (pose ids 0..2 for "a")
    values = [float(d.mean()) for k, d in cache["a"]["depth"].items()]
    assert len(values) == 6 and all(0.0 < x < 2.0 for x in values)


def _capsule_tosca(root: Path, n_poses: int = 4, bad_pose: int | None = None) -> None:
    cap = trimesh.creation.capsule(height=1.0, radius=0.2)
    root.mkdir()
    for cls in ("cat", "dog"):
        for pose in range(n_poses):
            v = cap.vertices + 0.08 * pose * np.stack([cap.vertices[:, 2] ** 2, 0 * cap.vertices[:, 2],
                                                       0 * cap.vertices[:, 2]], 1)
            f = cap.faces
            if cls == "dog" and pose == bad_pose:  # another connectivity: a subdivided capsule
                v, f = trimesh.remesh.subdivide(v, f)
            tosca.write_off(root / f"{cls}{pose}.off", v, f)


def test_datamodule_blends_enter_training_only(tmp_path):
    _capsule_tosca(tmp_path / "tosca", n_poses=5)
    kw = dict(source="tosca", root=str(tmp_path / "tosca"), image_size=32, split="pose", n_folds=2,
              batch_size=2, azimuths=[0.0, 30.0], eval_views=[0])
    plain = CanonicalDataModule.from_flat(str(tmp_path / "c"), **kw)
    plain.prepare_data()
    plain.setup()
    dm = CanonicalDataModule.from_flat(str(tmp_path / "c"), blend_poses=3, **kw)
    dm.setup()  # the same cache: blends are rendered in memory, not cached
    assert dm.config_hash() == plain.config_hash()
    extra = [r for r in dm.splits["train"] if r["pose"] >= BLEND_BASE]
    assert len(extra) == 2 * 3 * 2  # subjects x blends x training views
    assert len(dm.splits["train"]) == len(plain.splits["train"]) + len(extra)
    assert dm.splits["test"] == plain.splits["test"] and dm.splits["val"] == plain.splits["val"]
    for r in extra[:4]:
        item = dm.datasets["train"][dm.splits["train"].index(r)]
        assert item["mask"].sum() > 10 and item["depth"][item["mask"] > 0].min() >= 0.1
        truth = dm.cache[r["subject"]]["depth"][f"canonical_{r['view']}"]
        assert np.array_equal(item["canon_depth"][0].numpy(), truth)  # the subject's own canonical target


def test_subject_with_two_connectivities_is_named(tmp_path):
    _capsule_tosca(tmp_path / "tosca", n_poses=5, bad_pose=0)  # the canonical pose: every fold's endpoint
    dm = CanonicalDataModule.from_flat(str(tmp_path / "c"), source="tosca", root=str(tmp_path / "tosca"), image_size=32,
                             split="pose", n_folds=2, batch_size=2, blend_poses=20)
    dm.prepare_data()
    with pytest.raises(DataError, match=r"dog blend \d+ \(poses .*different vertex counts"):
        dm.setup()


@pytest.mark.skipif(not SHARED.is_dir(), reason="../shared/data/tosca8k not present")
def test_real_tosca_blends_render(tmp_path):
    dm = CanonicalDataModule.from_flat(str(tmp_path / "t"), source="tosca", root=str(SHARED), classes=["wolf", "centaur"],
                             image_size=32, split="pose", n_folds=2, view_mode="broadside", blend_poses=2)
    dm.prepare_data()
    dm.setup()
    extra = [i for i, r in enumerate(dm.splits["train"]) if r["pose"] >= BLEND_BASE]
    assert len(extra) == 4
    assert all(dm.datasets["train"][i]["mask"].sum() > 20 for i in extra)
