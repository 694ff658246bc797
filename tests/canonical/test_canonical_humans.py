"""Canonical forms of people: Anny bodies (sampling, the data source), the FAUST and Sumner readers,
scale-free depth, and the evaluation-only split."""

import numpy as np
import pytest
import trimesh

from datamodules.cache import DataError
from datamodules.canonical import CanonicalDataModule, posesets, tosca
from datamodules.canonical.tosca import MeshReadError
from lit3d.body_model import bodies
from tests.helpers.paths import SHARED_DATA

SHARED = SHARED_DATA


# ------------------------------------------------------------------ Anny sampling (no model needed)
def test_phenotypes_are_seeded_and_within_ranges():
    a, b = bodies.sample_phenotype(0, 3), bodies.sample_phenotype(0, 3)
    assert a == b and a != bodies.sample_phenotype(1, 3) and a != bodies.sample_phenotype(0, 4)
    for i in range(50):
        for k, v in bodies.sample_phenotype(7, i).items():
            lo, hi = bodies.PHENOTYPE_RANGES[k]
            assert lo <= v <= hi


def test_poses_are_seeded_within_limits_and_mirrored():
    p = bodies.sample_pose(0, 5)
    q = bodies.sample_pose(0, 5)
    assert all(np.array_equal(p[k], q[k]) for k in p)
    assert any(not np.array_equal(p[k], bodies.sample_pose(0, 6)[k]) for k in p)
    limits = {j.bone: j for j in bodies.JOINT_LIMITS}
    for i in range(40):
        pose = bodies.sample_pose(3, i)
        for bone, rv in pose.items():
            if bone.endswith(".R"):  # mirrored across x = 0: (x, y, z) -> (x, -y, -z)
                rv = rv * np.array([1.0, -1.0, -1.0])
                bone = bone[:-2] + ".L"
            if bone in limits:
                j = limits[bone]
                for value, (lo, hi) in zip(rv, (j.x, j.y, j.z)):
                    assert lo - 1e-12 <= value <= hi + 1e-12, (bone, value)
            elif bone == bodies.ELBOW[0]:
                angle = np.linalg.norm(rv)
                assert bodies.ELBOW[1] <= angle <= bodies.ELBOW[2] + 1e-12
                np.testing.assert_allclose(rv / max(angle, 1e-12), bodies.ELBOW_AXIS, atol=1e-9)
            else:
                assert bone == "root" and abs(np.degrees(rv[2])) <= 15.0 and rv[0] == rv[1] == 0
    half = bodies.sample_pose(3, 0, strength=0.5)
    full = bodies.sample_pose(3, 0)
    np.testing.assert_allclose(half["upperleg01.L"], 0.5 * full["upperleg01.L"])


def test_per_subject_poses_are_each_subjects_own_and_change_the_cache(tmp_path):
    own = [bodies.sample_pose(0, 3, subject=i) for i in (1, 2)]
    assert all(np.array_equal(own[0][k], bodies.sample_pose(0, 3, subject=1)[k]) for k in own[0])  # seeded
    assert any(not np.array_equal(own[0][k], own[1][k]) for k in own[0])  # two people, two poses
    assert any(not np.array_equal(own[0][k], bodies.sample_pose(0, 3)[k]) for k in own[0])  # not the shared draw
    kw = dict(source="anny", n_subjects=4, n_poses=4, image_size=48)
    shared = CanonicalDataModule.from_flat(str(tmp_path / "a"), **kw)
    assert shared.config_hash() == CanonicalDataModule.from_flat(str(tmp_path / "a"), pose_draw="shared", **kw).config_hash()
    assert "pose_draw" not in shared.cache_config()  # old caches keep their hash
    assert CanonicalDataModule.from_flat(str(tmp_path / "a"), pose_draw="per_subject", **kw).config_hash() != shared.config_hash()
    from datamodules.canonical.sources import AnnySource

    with pytest.raises(DataError, match="unknown pose_draw 'each'"):
        AnnySource(4, 4, 0, 0, 15.0, 1.0, pose_draw="each")


# ------------------------------------------------------------------ Anny bodies (the real model)
@pytest.fixture(scope="module")
def body_model():
    return bodies.BodyModel()


def _edge_lengths(v, f):
    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    return np.linalg.norm(v[e[:, 0]] - v[e[:, 1]], axis=1)


def test_anny_bodies_are_people_in_plausible_poses(body_model):
    """Rest pose: y up, facing +z, 1.2-2.1 m tall; posed bodies keep their surface (edges stretch
    by under a few percent: no broken limbs) and differ from the rest pose; phenotypes change shape."""
    f = body_model.faces
    pheno = bodies.sample_phenotype(0, 0)
    rest, *posed = body_model.vertices(pheno, [None] + [bodies.sample_pose(0, i) for i in range(6)])
    ext = rest.max(0) - rest.min(0)
    assert np.argmax(ext) == 1 and 1.2 < ext[1] < 2.1
    y0 = rest[:, 1].min()  # toes point to the camera (+z): far in front of the shins, heels just behind
    feet, shins = rest[rest[:, 1] < y0 + 0.05, 2], rest[(rest[:, 1] > y0 + 0.25) & (rest[:, 1] < y0 + 0.35), 2]
    assert feet.max() - shins.mean() > 2 * (shins.mean() - feet.min()) > 0
    base = _edge_lengths(rest, f)
    for v in posed:
        ratio = _edge_lengths(v, f) / np.maximum(base, 1e-9)
        assert np.median(np.abs(ratio - 1)) < 0.02 and np.quantile(ratio, 0.99) < 1.6
        assert np.abs(v - rest).max() > 0.1  # the pose moved something
    other = body_model.vertices(bodies.sample_phenotype(0, 1), [None])[0]
    assert np.abs(other - rest).max() > 0.02


def test_anny_datamodule_pairs_share_each_subjects_canonical(tmp_path):
    dm = CanonicalDataModule.from_flat(str(tmp_path / "anny"), source="anny", n_subjects=4, n_poses=4, image_size=48,
                             split="subject_pose", n_folds=2, split_seed=0, seed=1, batch_size=4)
    dm.prepare_data()
    dm.setup()
    man = dm.manifest
    assert man["subjects"] == ["anny0000", "anny0001", "anny0002", "anny0003"]
    assert set(man["categories"].values()) == {"human"} and man["config"]["bodies"][0] == bodies.BODIES_VERSION
    batch = next(iter(dm.test_dataloader()))
    assert batch["depth"].shape[1:] == (1, 48, 48)
    same = batch["subject_idx"][0] == batch["subject_idx"]
    assert np.allclose(batch["canon_depth"][same].numpy(), batch["canon_depth"][0].numpy())
    assert not np.allclose(batch["depth"][0].numpy(), batch["canon_depth"][0].numpy())
    from PIL import Image

    dm.show(2, tmp_path / "sheet.png")  # the depth pairs and the shaded bodies beside them
    shaded = Image.open(tmp_path / "sheet_shaded.png")
    assert shaded.size == (170 + 5 * 256, 2 * 44 + 2 * 256)  # canonical + 4 poses, 2 subjects, 256 px panels
    cells = np.asarray(shaded.convert("L"))[88:, 170:]
    assert (cells < 200).mean() > 0.03  # bodies drawn, not blank panels
    te = {r["subject"] for r in dm.splits["test"]}
    assert te and not te & {r["subject"] for r in dm.splits["train"]}
    # a second training seed keeps the people and the split (split_seed, body_seed)
    dm2 = CanonicalDataModule.from_flat(str(tmp_path / "anny"), source="anny", n_subjects=4, n_poses=4, image_size=48,
                              split="subject_pose", n_folds=2, split_seed=0, seed=2, batch_size=4)
    assert dm2.config_hash() == dm.config_hash()
    dm2.setup()
    assert dm2.splits["test"] == dm.splits["test"]
    # the contact sheet labels each person with the phenotype drawn from body_seed (the cache holds none)
    for s in man["subjects"]:
        assert dm.source.phenotype(s) == bodies.sample_phenotype(0, int(s[len("anny"):]))
    assert dm.source.phenotype("anny0000") != dm.source.phenotype("anny0001")


# ------------------------------------------------------------------ FAUST and Sumner readers
def _blob(seed=0, scale=1.0):
    m = trimesh.creation.capsule(height=1.0, radius=0.2, count=[12, 12])
    rng = np.random.default_rng(seed)
    v = m.vertices * np.array([1.0 + 0.3 * rng.random(), 1.0, 1.0])
    v = v[:, [0, 2, 1]]  # capsule along y (up)
    return v * scale, m.faces.astype(np.int64)


def test_faust_names_in_every_layout(tmp_path):
    assert posesets.faust_subject_pose("subject3_pose7.off") == (3, 7)
    assert posesets.faust_subject_pose("tr_reg_037.ply") == (3, 7)
    assert posesets.faust_subject_pose("085.off") == (8, 5)
    assert posesets.faust_subject_pose("cat3.off") is None
    v, f = _blob()
    for name in ("subject0_pose0.off", "subject0_pose1.off", "tr_reg_010.off", "tr_reg_011.obj", "notes.txt"):
        p = tmp_path / name
        if name.endswith(".txt"):
            p.write_text("x")
        elif name.endswith(".obj"):
            trimesh.Trimesh(v, f, process=False).export(p)
        else:
            tosca.write_off(p, v, f)
    tosca.write_off(tmp_path / "tr_reg_011.off", v, f)  # the same shape twice: .off preferred
    items = posesets.index_faust(tmp_path)
    assert sorted(items) == [("subject0", 0), ("subject0", 1), ("subject1", 0), ("subject1", 1)]
    assert items[("subject1", 1)].suffix == ".off"


def test_faust_and_sumner_errors_name_the_folder(tmp_path):
    with pytest.raises(MeshReadError, match="no FAUST meshes"):
        posesets.index_faust(tmp_path)
    with pytest.raises(MeshReadError, match="not found"):
        posesets.index_faust(tmp_path / "missing")
    v, f = _blob()
    (tmp_path / "cat").mkdir()
    trimesh.Trimesh(v, f, process=False).export(tmp_path / "cat" / "cat-01.obj")
    with pytest.raises(MeshReadError, match="no reference pose .* for cat"):
        posesets.index_sumner(tmp_path)
    tosca.write_off(tmp_path / "subject0_pose1.off", v, f)
    with pytest.raises(DataError, match="no canonical pose 0 for subject"):
        CanonicalDataModule.from_flat(str(tmp_path / "c"), source="faust", root=str(tmp_path), image_size=32).source


def test_sumner_reference_is_pose_zero(tmp_path):
    v, f = _blob()
    for animal in ("cat", "lion"):
        (tmp_path / animal).mkdir()
        for name in ("reference", "01", "02"):
            trimesh.Trimesh(v, f, process=False).export(tmp_path / animal / f"{animal}-{name}.obj")
    items = posesets.index_sumner(tmp_path)
    assert sorted(items) == [(a, p) for a in ("cat", "lion") for p in (0, 1, 2)]
    assert items[("cat", 0)].name == "cat-reference.obj"
    assert sorted(posesets.index_sumner(tmp_path, ["lion"])) == [("lion", 0), ("lion", 1), ("lion", 2)]


def test_depth_is_scale_free_and_split_all_tests_every_item(tmp_path):
    """A FAUST folder in metres and the same folder at unit area (scaled by 0.6, moved) give the
    same depth images; ``split=all`` makes every mesh, the canonical pose included, a test item."""
    for root, scale, shift in (("m", 1.0, 0.0), ("unit", 0.6, 3.0)):
        (tmp_path / root).mkdir()
        for s in range(2):
            for p in range(3):
                v, f = _blob(seed=10 * s + p)
                tosca.write_off(tmp_path / root / f"subject{s}_pose{p}.off", v * scale + shift, f)
    dms = [CanonicalDataModule.from_flat(str(tmp_path / f"cache_{r}"), source="faust", root=str(tmp_path / r),
                               image_size=48, split="all", n_folds=1, batch_size=16) for r in ("m", "unit")]
    for dm in dms:
        dm.prepare_data()
        dm.setup()
    a, b = (next(iter(dm.test_dataloader())) for dm in dms)
    np.testing.assert_allclose(a["depth"].numpy(), b["depth"].numpy(), atol=2e-3)
    assert sorted((r["subject"], r["pose"]) for r in dms[0].splits["test"]) == [
        (f"subject{s}", p) for s in range(2) for p in range(3)]
    assert dms[0].splits["train"] == [] and "train" not in dms[0].datasets


# ------------------------------------------------------------------ the real sets (skip when absent)
@pytest.mark.skipif(not (SHARED / "faust_a").is_dir(), reason="../shared/data/faust_a is not on this machine")
def test_real_faust_is_five_subjects_by_ten_poses():
    items = posesets.index_faust(SHARED / "faust_a")
    assert len(items) == 50 and {s for s, _ in items} == {f"subject{i}" for i in range(5)}
    v, f = tosca.read_mesh(items[("subject3", 7)])
    assert 4990 < len(v) < 5010 and np.ptp(v, 0).argmax() == 1  # vertices kept (no merging), y up


@pytest.mark.skipif(not (SHARED / "sumner_poses").is_dir(), reason="../shared/data/sumner_poses is not on this machine")
def test_real_sumner_is_four_animals_with_references():
    items = posesets.index_sumner(SHARED / "sumner_poses")
    counts = {a: sum(1 for b, _ in items if b == a) for a in ("cat", "horse", "elephant", "lion")}
    assert counts == {"cat": 10, "horse": 11, "elephant": 11, "lion": 10}


def test_adult_phenotypes_come_from_annys_shape_distribution(body_model):
    """phenotypes="adult": realistic adults (the uniform draw gave heights up to 2.36 m and teenagers)."""
    draws = [bodies.sample_phenotype(0, i, "adult", body_model.model) for i in range(24)]
    assert draws[3] == bodies.sample_phenotype(0, 3, "adult", body_model.model)  # seeded per subject
    assert len({round(d["height"], 6) for d in draws}) == 24
    assert min(d["age"] for d in draws) > 0.7  # Anny's age 2/3 = young adult
    assert max(d["height"] for d in draws) < 0.7 and min(d["height"] for d in draws) > 0.1
    uniform = [bodies.sample_phenotype(0, i) for i in range(24)]
    assert max(d["height"] for d in uniform) > max(d["height"] for d in draws)
    with pytest.raises(ValueError, match="phenotype mode"):
        bodies.sample_phenotype(0, 0, "teen", body_model.model)


def test_validation_subjects_are_neither_tested_nor_trained_on():
    from datamodules.canonical.splits import split_subject_pose

    subjects, poses = [f"s{i}" for i in range(20)], list(range(10))
    out = split_subject_pose(subjects, poses, 5, 0, seed=3, val_subjects=3)
    test_s, val_s, train_s = ({s for s, _ in out[k]} for k in ("test", "val", "train"))
    test_p, val_p, train_p = ({p for _, p in out[k]} for k in ("test", "val", "train"))
    assert len(val_s) == 3 and not (val_s & test_s) and not (val_s & train_s) and not (test_s & train_s)
    assert not (test_p & train_p) and not (test_p & val_p) and val_p == train_p
    assert len(out["test"]) == 4 * 2 and len(out["train"]) == 13 * 8 and len(out["val"]) == 3 * 8
    old = split_subject_pose(subjects, poses, 5, 0, seed=3)  # the old rule: test subjects in validation
    assert {s for s, _ in old["val"]} & test_s
