"""Synthetic figures, depth camera, canonical DataModule (cache, manifest, strict splits), TOSCA source."""
import json

import numpy as np
import pytest
import torch
import trimesh
from PIL import Image

from datamodules.canonical import CanonicalDataModule, DataError, split_pose, split_subject_pose
from datamodules.canonical import tosca
from datamodules.canonical.sources import SynthSource
from datamodules.canonical.splits import OWN_POSE_BASE, fold_pairs
from datamodules.canonical.figures import KINDS, figure_mesh, joint_positions, make_pose, make_subject
from lit3d.render.depth import depth_to_mesh, depth_to_points, render_depth
from tests.helpers.entry_points import Ctx, data_cli
from tests.helpers.paths import SHARED_DATA

SHARED = SHARED_DATA / "tosca8k"


@pytest.mark.parametrize("kind", KINDS)
def test_figures_are_closed_posed_and_subject_specific(kind):
    s1, s2 = make_subject(kind, 1), make_subject(kind, 2)
    assert not np.allclose(s1.offsets, s2.offsets)  # proportions differ per subject
    v, f = figure_mesh(s1, None, resolution=32)
    m = trimesh.Trimesh(v, f)
    assert m.is_watertight and m.volume > 0
    p = make_pose(kind, 3)
    assert np.allclose(joint_positions(s1, p)[0], joint_positions(s1)[0])  # root stays
    assert not np.allclose(joint_positions(s1, p), joint_positions(s1))
    # the same pose index gives the same joint angles for every subject
    assert all(np.allclose(a, b) for a, b in zip(make_pose(kind, 3).values(), p.values()))


def test_per_subject_figure_poses_are_each_figures_own_and_change_the_cache(tmp_path):
    def rotations(draw, subject):
        src = SynthSource(["humanoid"], 3, 4, 0, 32, 0, 15.0, 1.0, pose_draw=draw)
        return src._posing(subject, 2)[1:3]

    (a, ya), (b, yb) = rotations("per_subject", "humanoid001"), rotations("per_subject", "humanoid002")
    assert any(not np.allclose(a[k], b[k]) for k in a) and ya != yb  # two figures, two poses
    again, _ = rotations("per_subject", "humanoid001")
    assert all(np.array_equal(a[k], again[k]) for k in a)  # seeded
    shared = [rotations("shared", s)[0] for s in ("humanoid001", "humanoid002")]
    assert all(np.array_equal(shared[0][k], shared[1][k]) for k in shared[0])  # the old draw: one pose for all
    kw = dict(n_subjects=3, n_poses=4, image_size=32, kinds=["humanoid"])
    old = CanonicalDataModule.from_flat(str(tmp_path), **kw)
    assert "pose_draw" not in old.cache_config()  # shared caches keep their hash
    assert CanonicalDataModule.from_flat(str(tmp_path), pose_draw="per_subject", **kw).config_hash() != old.config_hash()
    with pytest.raises(DataError, match="unknown pose_draw 'each'"):
        SynthSource(["humanoid"], 3, 4, 0, 32, 0, 15.0, 1.0, pose_draw="each")


def test_depth_camera_is_linear_and_back_projects():
    box = trimesh.creation.box(extents=(0.6, 0.6, 0.4))  # front face at z = +0.2 -> distance 1.8
    d, m = render_depth(box.vertices, box.faces, 64)
    assert m[32, 32] and not m[0, 0] and d[0, 0] == 0
    expected = 1 - 0.9 * (1.8 - 1.5)  # = 0.73
    assert d[m].mean() == pytest.approx(expected, abs=2e-3)
    pts = depth_to_points(d, m)
    assert pts[:, 2].mean() == pytest.approx(0.2, abs=3e-3)
    assert np.abs(pts[:, :2]).max() == pytest.approx(0.3, abs=0.02)
    v, f = depth_to_mesh(d, m)
    assert len(v) == m.sum() and len(f) > 0
    n = trimesh.Trimesh(v, f).face_normals
    assert (n[:, 2] > 0.9).all()  # faces look at the camera


def _dm(tmp_path, **kw):
    args = dict(image_size=32, n_subjects=6, n_poses=6, mesh_resolution=24, n_folds=3, batch_size=4,
                kinds=["humanoid", "quadruped"], seed=1)
    args.update(kw)
    return CanonicalDataModule.from_flat(str(tmp_path / "data"), **args)


def test_datamodule_cache_manifest_and_strict_split(tmp_path):
    dm = _dm(tmp_path)
    dm.prepare_data()
    man = json.loads((tmp_path / "data" / "manifest.json").read_text())
    assert man["complete"] and man["config_hash"] == dm.config_hash() and len(man["subjects"]) == 6
    dm.setup()
    info = dm.describe()
    assert info["train"]["items"] == 16 and info["test"]["items"] == 4 and info["val"]["items"] == 16
    tr = dm.splits["train"]
    te = dm.splits["test"]
    assert not {r["subject"] for r in te} & {r["subject"] for r in tr}
    assert not {r["pose"] for r in te} & {r["pose"] for r in tr}
    b = next(iter(dm.train_dataloader()))
    assert b["depth"].shape == b["canon_mask"].shape == (4, 1, 32, 32)
    assert float(b["depth"].max()) <= 1 and float(b["depth"][b["mask"] > 0].min()) >= 0.1 - 1e-3
    assert ((b["depth"] > 0) == (b["mask"] > 0)).all()
    png = dm.show(3, tmp_path / "show.png")
    assert png.stat().st_size > 100
    width, height = Image.open(png).size  # 4 labelled columns, 3 rows, the 32 px images enlarged to 256 px
    assert width >= 4 * 256 and height >= 3 * 256
    # a second module with the same config reuses the cache (no rendering)
    first = tmp_path / "data" / "subjects" / f"{man['subjects'][0]}.npz"
    assert [it["file"] for it in man["items"]] == [f"subjects/{s}.npz" for s in man["subjects"]]
    mtime = first.stat().st_mtime
    dm2 = _dm(tmp_path)
    dm2.prepare_data()
    assert first.stat().st_mtime == mtime


def test_interrupted_preparation_resumes(tmp_path, monkeypatch):
    dm = _dm(tmp_path, n_subjects=4, n_poses=3, n_folds=2)
    # a cache of the layout before CacheBuilder (one <subject>.npz beside its manifest) is replaced
    legacy = tmp_path / "data" / "humanoid000.npz"
    legacy.parent.mkdir()
    legacy.write_bytes(b"old")
    (tmp_path / "data" / "manifest.json").write_text(json.dumps(
        {"generator_version": "canonical-data-1", "complete": True, "subjects": ["humanoid000"]}))
    calls = []
    orig = dm._render_subject

    def flaky(s):
        calls.append(s)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return orig(s)

    monkeypatch.setattr(dm, "_render_subject", flaky)
    with pytest.raises(KeyboardInterrupt):
        dm.prepare_data()
    assert not (tmp_path / "data" / "manifest.json").exists()  # written last, by a complete preparation
    assert len(list((tmp_path / "data" / "subjects").glob("*.npz"))) == 2
    assert not list((tmp_path / "data").rglob(".*.tmp"))
    dm2 = _dm(tmp_path, n_subjects=4, n_poses=3, n_folds=2)
    rendered = []
    orig2 = dm2._render_subject
    monkeypatch.setattr(dm2, "_render_subject", lambda s: rendered.append(s) or orig2(s))
    dm2.prepare_data()
    assert len(rendered) == 2 and json.loads((tmp_path / "data" / "manifest.json").read_text())["complete"]
    assert not legacy.exists()


def test_split_functions_cover_every_fold():
    subjects, poses = [f"s{i}" for i in range(6)], list(range(6))
    tested = set()
    for fold in range(3):
        sp = split_subject_pose(subjects, poses, 3, fold, seed=0)
        assert len(sp["train"]) == 16 and len(sp["test"]) == 4
        tested |= set(sp["test"])
    assert len({s for s, _ in tested}) == 6 and len({p for _, p in tested}) == 6
    ps = split_pose({"cat": [1, 2, 3, 4, 5, 6], "wolf": [1, 2]}, 3, 0, seed=0)
    assert not set(ps["test"]) & set(ps["train"])
    assert {s for s, _ in ps["test"]} == {"cat", "wolf"}
    with pytest.raises(DataError, match="needs at least"):
        split_subject_pose(subjects[:2], poses, 3, 0, 0)


def test_bad_config_is_named(tmp_path):
    with pytest.raises(DataError, match="needs root"):
        CanonicalDataModule.from_flat(str(tmp_path), image_size=32, source="tosca")
    with pytest.raises(DataError, match="unknown canonical data source"):
        CanonicalDataModule.from_flat(str(tmp_path), image_size=32, source="nope")


@pytest.mark.parametrize("override,key,tag", [("+data.render.forward_flow=true", "data.render.forward_flow", True),
                                              ("+data.training.batch_poses=4", "data.training.batch_poses", True),
                                              ("+data.phenotype_targets=true", "phenotype_targets", False)])
def test_a_removed_data_option_is_refused_naming_it(override, key, tag, tmp_path, capsys, monkeypatch):
    """The parked options' data keys (git tag parked-canonical-options) are gone: lit3d-data stops before any
    work with exit 2 and one line naming the key (and, for a key of a settings node, the tag), instead of
    running their old code."""
    arg = f"experiment=canonical_tiny {override} paths.data_dir={tmp_path}/data hydra.run.dir={tmp_path}/run"
    out = data_cli(arg, Ctx(tmp_path, capsys, monkeypatch, None))
    lines = [ln for ln in out.err.splitlines() if ln.strip()]
    assert out.code == 2 and len(lines) == 1 and lines[0].startswith("error: data config: "), out
    assert key in lines[0] and (f"{key}: removed" in lines[0] and "git tag parked-canonical-options" in lines[0]) == tag
    assert not (tmp_path / "data").exists()


def test_tosca_source_on_written_files(tmp_path):
    v = trimesh.creation.capsule(height=1.0, radius=0.2).vertices
    f = trimesh.creation.capsule(height=1.0, radius=0.2).faces
    root = tmp_path / "tosca"
    root.mkdir()
    rng = np.random.default_rng(0)
    for cls in ("cat", "dog"):
        for pose in (0, 1, 3, 4):
            bent = v + 0.05 * pose * np.stack([v[:, 2] ** 2, 0 * v[:, 2], 0 * v[:, 2]], 1)
            (tosca.write_mat if pose % 2 else tosca.write_off)(root / f"{cls}{pose}.{'mat' if pose % 2 else 'off'}",
                                                               bent * (1 + 0.1 * rng.random()), f)
    dm = CanonicalDataModule.from_flat(str(tmp_path / "c"), source="tosca", root=str(root), image_size=32, split="pose",
                             n_folds=3, batch_size=2)
    dm.prepare_data()
    dm.setup()
    info = dm.describe()
    assert info["subjects"] == 2 and info["test"]["items"] == 2 and info["train"]["items"] == 2
    assert info["val"]["items"] == 2


@pytest.mark.skipif(not SHARED.is_dir(), reason="../shared/data/tosca8k not present")
def test_real_tosca8k_renders(tmp_path):
    dm = CanonicalDataModule.from_flat(str(tmp_path / "t"), source="tosca", root=str(SHARED), classes=["wolf", "centaur"],
                             image_size=32, split="pose", n_folds=2)
    dm.prepare_data()
    dm.setup()
    b = dm.datasets["test"][0]
    assert b["mask"].sum() > 20 and b["canon_mask"].sum() > 20


def test_subject_balanced_sampler_draws_subjects_equally():
    """20 items of one subject, 2 of another: each subject ~half of the draws, reproducible by seed."""
    from collections import Counter

    from datamodules.canonical import subject_balanced_sampler

    records = [{"subject": "michael"}] * 20 + [{"subject": "wolf"}] * 2
    sampler = subject_balanced_sampler(records, seed=0)  # its generator moves on epoch after epoch
    draws = [records[i]["subject"] for _ in range(200) for i in sampler]
    share = Counter(draws)["wolf"] / len(draws)
    assert abs(share - 0.5) < 0.03, share
    assert list(subject_balanced_sampler(records, 3)) == list(subject_balanced_sampler(records, 3))


def test_pose_split_tests_every_pose_exactly_once_even_with_fewer_poses_than_folds():
    from datamodules.canonical.splits import split_pose

    subject_poses = {"wolf": [1, 2], "cat": [1, 2, 3, 4, 5], "horse": [1, 2, 3], "gorilla": [7]}
    n_folds = 3
    tested = [sp for f in range(n_folds) for sp in split_pose(subject_poses, n_folds, f, seed=0)["test"]]
    expected = [(s, p) for s, ps in subject_poses.items() if len(ps) >= 2 for p in ps]
    assert sorted(tested) == sorted(expected)  # each once: no pose of wolf held out by two folds
    for f in range(n_folds):
        sp = split_pose(subject_poses, n_folds, f, seed=0)
        test = set(sp["test"])
        assert not test & set(sp["train"]) and not test & set(sp["val"])


@pytest.mark.parametrize("view_mode", ["fixed", "broadside"])
def test_flip_lr_mirrors_the_target_only_when_input_and_target_share_the_camera(tmp_path, view_mode):
    """broadside: the target's view is the canonical shape's own (the same image for every item of a
    subject, as the evaluation expects), so a mirrored input keeps the unmirrored target; mirroring
    it too (the old behaviour) trained half the targets on a view the evaluation never asks for.
    fixed: one camera for both, so input and target are mirrored together."""
    import torch

    dm = CanonicalDataModule.from_flat(str(tmp_path / "data"), image_size=32, n_subjects=3, n_poses=3, mesh_resolution=16,
                             n_folds=3, batch_size=4, kinds=["quadruped"], seed=1, split="pose",
                             view_mode=view_mode, flip_lr=True)
    dm.prepare_data()
    dm.setup()
    ds = dm.datasets["train"]
    torch.manual_seed(0)
    flipped = kept = 0
    for _ in range(4):
        for i, r in enumerate(ds.records):
            it, c = ds[i], dm.cache[r["subject"]]
            posed, canon = c["depth"][f"{r['pose']}_{r['view']}"], c["depth"][f"canonical_{r['view']}"]
            assert not np.array_equal(canon, canon[:, ::-1])  # a mirror would be visible
            mirrored = np.array_equal(it["depth"][0].numpy(), posed[:, ::-1])
            assert mirrored or np.array_equal(it["depth"][0].numpy(), posed)
            target = canon[:, ::-1] if (mirrored and view_mode == "fixed") else canon
            assert np.array_equal(it["canon_depth"][0].numpy(), target)
            assert np.array_equal(it["canon_mask"][0].numpy() > 0.5, (target > 0))
            flipped, kept = flipped + mirrored, kept + (not mirrored)
    assert flipped and kept  # both cases were drawn
    assert not dm.datasets["test"].flip_lr


def test_eval_views_train_on_every_azimuth_and_evaluate_the_chosen_ones(tmp_path):
    """Extra azimuths are training augmentation: train sees every view, val/test and the pooled held-out
    set only ``eval_views``; a mirrored broadside input of a turned view gets the canonical image of the
    opposite turn."""
    import torch

    from datamodules.canonical.datamodule import mirror_views

    assert mirror_views([0.0, -25.0, 25.0]) == {0: 0, 1: 2, 2: 1}
    assert mirror_views([0.0, 30.0]) == {0: 0, 1: 1}  # no opposite turn: the same view
    dm = CanonicalDataModule.from_flat(str(tmp_path / "data"), image_size=32, n_subjects=3, n_poses=3, mesh_resolution=16,
                             n_folds=3, batch_size=4, kinds=["quadruped"], seed=1, split="pose",
                             view_mode="broadside", azimuths=[0.0, -25.0, 25.0], eval_views=[0], flip_lr=True)
    dm.prepare_data()
    dm.setup()
    assert {r["view"] for r in dm.splits["train"]} == {0, 1, 2}
    assert {r["view"] for r in dm.splits["test"]} == {0} and {r["view"] for r in dm.splits["val"]} == {0}
    assert {r["view"] for r in dm.held_out_records()} == {0}
    assert len(dm.splits["train"]) == 3 * len({(r["subject"], r["pose"]) for r in dm.splits["train"]})
    ds = dm.datasets["train"]
    torch.manual_seed(0)
    seen = set()
    for _ in range(6):
        for i, r in enumerate(ds.records):
            it, c = ds[i], dm.cache[r["subject"]]
            posed = c["depth"][f"{r['pose']}_{r['view']}"]
            mirrored = np.array_equal(it["depth"][0].numpy(), posed[:, ::-1])
            want = {0: 0, 1: 2, 2: 1}[r["view"]] if mirrored else r["view"]
            assert np.array_equal(it["canon_depth"][0].numpy(), c["depth"][f"canonical_{want}"])
            seen.add((r["view"], mirrored))
    assert (1, True) in seen and (1, False) in seen
    with pytest.raises(DataError, match="eval_views"):
        CanonicalDataModule.from_flat(str(tmp_path / "x"), image_size=32, azimuths=[0.0, 30.0], eval_views=[2])


def test_roll_turns_the_input_only_and_keeps_depth_inside_the_mask(tmp_path):
    """roll: a horizontal bar turned by 90 degrees is the vertical bar through the centre, nothing lost,
    no depth outside the mask; the datamodule rolls training inputs only, never the target."""
    import torch

    from datamodules.canonical.dataset import roll

    d = torch.zeros(1, 32, 32)
    d[0, 14:18, 4:28] = 0.7  # horizontal bar through the centre (rows 14-17)
    m = (d > 0).float()
    rd, rm = roll(d, m, 90.0)
    assert torch.equal(rm[0], m[0].T)  # symmetric about the centre: a quarter turn is the transpose
    assert (rd[rm == 0] == 0).all() and torch.allclose(rd[rm > 0], torch.tensor(0.7))
    dm = CanonicalDataModule.from_flat(str(tmp_path / "data"), image_size=32, n_subjects=3, n_poses=3, mesh_resolution=16,
                             n_folds=3, batch_size=4, kinds=["quadruped"], seed=1, split="pose",
                             view_mode="broadside", roll_deg=45.0)
    dm.prepare_data()
    dm.setup()
    torch.manual_seed(0)
    ds, turned = dm.datasets["train"], 0
    for i, r in enumerate(ds.records):
        it, c = ds[i], dm.cache[r["subject"]]
        turned += not np.array_equal(it["mask"][0].numpy() > 0.5, c["mask"][f"{r['pose']}_{r['view']}"] > 0)
        assert np.array_equal(it["canon_depth"][0].numpy(), c["depth"][f"canonical_{r['view']}"])
    assert turned > 0
    assert dm.datasets["test"].roll_deg == 0 and dm.datasets["val"].roll_deg == 0


def test_train_pose_fraction_thins_training_poses_per_subject_and_keeps_the_test(tmp_path):
    """The learning-curve knob: that share of each subject's training poses (at least one, seeded),
    validation and test unchanged; a fraction outside (0, 1] is a named error."""
    from datamodules.canonical.splits import thin_training

    train = [(s, p) for s in ("a", "b") for p in range(8)] + [("c", 1)]
    half = thin_training(train, 0.5, seed=3)
    assert set(half) < set(train) and half == thin_training(train, 0.5, seed=3)
    assert [sum(s == k for s, _ in half) for k in "abc"] == [4, 4, 1]  # c keeps its only pose
    assert thin_training(train, 1.0, seed=3) == train
    assert set(thin_training(train, 0.5, seed=4)) != set(half)  # the seed draws the poses
    for bad in (0.0, 1.5):
        with pytest.raises(DataError, match="train_pose_fraction must be in"):
            thin_training(train, bad, seed=0)

    def dm(fraction):
        d = CanonicalDataModule.from_flat(str(tmp_path / "data"), image_size=32, n_subjects=2, n_poses=8, mesh_resolution=16,
                                n_folds=2, batch_size=4, kinds=["humanoid"], seed=1, split="pose",
                                train_pose_fraction=fraction)
        d.prepare_data()
        d.setup()
        return d

    full, thin = dm(1.0), dm(0.5)
    assert thin.splits["test"] == full.splits["test"] and thin.splits["val"] == full.splits["val"]
    poses = {k: {(r["subject"], r["pose"]) for r in d.splits["train"]} for k, d in (("full", full), ("thin", thin))}
    assert poses["thin"] < poses["full"]
    for subject in full.cache:
        n = sum(s == subject for s, _ in poses["full"])
        assert sum(s == subject for s, _ in poses["thin"]) == max(1, round(0.5 * n))


def test_own_poses_train_only_and_each_figures_own(tmp_path):
    """data.source.own_poses: every figure N poses of its own, given to training only; the test keeps the poses
    that every figure shares, and no two figures share an own pose."""
    subject_poses = {f"s{i}": [0, 1, 2, OWN_POSE_BASE, OWN_POSE_BASE + 1] for i in range(6)}
    pairs = fold_pairs(subject_poses, "subject_pose", 3, 0, seed=0, val_subjects=1)
    plain = fold_pairs({s: [0, 1, 2] for s in subject_poses}, "subject_pose", 3, 0, seed=0, val_subjects=1)
    assert pairs["test"] == plain["test"] and pairs["val"] == plain["val"]
    training = sorted({s for s, _ in plain["train"]})
    assert sorted(pairs["train"]) == sorted(plain["train"] + [(s, OWN_POSE_BASE + k) for s in training for k in (0, 1)])
    dm = _dm(tmp_path, own_poses=2, flow_targets=True, val_subjects=1)
    assert dm.config_hash() != _dm(tmp_path).config_hash()
    dm.prepare_data()
    dm.setup()
    train_subjects = {r["subject"] for r in dm.splits["train"]}
    own = [r for r in dm.splits["train"] if r["pose"] >= OWN_POSE_BASE]
    assert len(own) == 2 * len(train_subjects) and all(r["pose"] < OWN_POSE_BASE for k in ("val", "test") for r in dm.splits[k])
    a, b = sorted(s for s in train_subjects if dm.source.category(s) == "humanoid")[:2]
    first = dm.datasets["train"]
    depth = {(r["subject"], r["pose"]): first[i]["mask"] for i, r in enumerate(dm.splits["train"])}
    assert not torch.equal(depth[(a, OWN_POSE_BASE)], depth[(b, OWN_POSE_BASE)])  # each figure's own pose
    assert all(bool(first[i]["has_flow"]) for i, r in enumerate(dm.splits["train"]) if r["pose"] >= OWN_POSE_BASE)
    with pytest.raises(DataError, match=r"data.source \(tosca\).own_poses: not a setting"):  # only synth has them
        CanonicalDataModule(str(tmp_path / "t"), 32, source={"kind": "tosca", "own_poses": 2}, root=str(tmp_path))


def test_val_poses_own_validates_new_poses_of_the_validation_subjects():
    """data.split.val_poses=own: the validation subjects in their own poses (none of them in any training pair);
    training and test unchanged; refused without own poses or for an unknown name."""
    subject_poses = {f"s{i}": [0, 1, 2, OWN_POSE_BASE, OWN_POSE_BASE + 1] for i in range(6)}
    plain = fold_pairs(subject_poses, "subject_pose", 3, 0, seed=0, val_subjects=1)
    own = fold_pairs(subject_poses, "subject_pose", 3, 0, seed=0, val_subjects=1, val_poses="own")
    assert own["train"] == plain["train"] and own["test"] == plain["test"]
    (val_subject,) = {s for s, _ in plain["val"]}
    assert own["val"] == [(val_subject, OWN_POSE_BASE), (val_subject, OWN_POSE_BASE + 1)]
    assert not set(own["val"]) & set(own["train"]) and val_subject not in {s for s, _ in own["train"]}
    with pytest.raises(DataError, match="poses of their own"):
        fold_pairs({s: [0, 1, 2] for s in subject_poses}, "subject_pose", 3, 0, seed=0, val_subjects=1, val_poses="own")
    with pytest.raises(DataError, match="val_poses"):
        fold_pairs(subject_poses, "subject_pose", 3, 0, seed=0, val_subjects=1, val_poses="new")
    with pytest.raises(DataError, match="val_subjects"):
        fold_pairs(subject_poses, "subject_pose", 3, 0, seed=0, val_poses="own")
