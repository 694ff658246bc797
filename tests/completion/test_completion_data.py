"""Synthetic shape-completion data: geometry, determinism, cache, resume, DataModule API."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch

from datamodules.cache import MANIFEST, MARKER, DataError
from datamodules.completion import CompletionDataModule
from datamodules.completion import sources as completion_sources
from datamodules.completion.depth_voxels import (
    VIEW_SETS, ViewGeometry, make_sample, max_pool, solid_occupancy,
)
from datamodules.completion.furniture import GENERATORS, Shape, box, make_shape
from datamodules.completion.voxel_cache import load_pair, save_pair
from lit3d.sensing.placement import camera_rotation
from lit3d.utils.shapenet_categories import SEEN_CATEGORIES, UNSEEN_CATEGORIES

SMALL = {"train": 8, "val": 4, "test_same": 4, "test_cross": 4, "test_unseen": 24}


def small_dm(data_dir: Path, seed: int = 0, **kw) -> CompletionDataModule:
    return CompletionDataModule(data_dir=str(data_dir), seed=seed, target_res=32, input_factor=4,
                                sizes=SMALL, batch_size=4, prepare={"progress": False}, **kw)


def contents(dm: CompletionDataModule) -> dict[str, tuple[bytes, bytes]]:
    m = json.loads((dm.data_dir / MANIFEST).read_text())
    out = {}
    for it in m["items"]:
        a, b = load_pair(dm.data_dir / it["file"])
        out[it["file"]] = (np.packbits(a).tobytes(), np.packbits(b).tobytes())
    return out


@pytest.fixture(scope="module")
def prepared(tmp_path_factory):
    dm = small_dm(tmp_path_factory.mktemp("synth") / "a")
    dm.prepare_data()
    dm.setup()
    return dm


# ---------------------------------------------------------------- geometry
def test_box_front_face_is_the_partial_input():
    """An axis-aligned box seen head-on: the 2.5D surface is the target's near (k-min) face.

    The target is grown by half a voxel (conservative), so its face may have a one-voxel
    rim more than the rendered silhouette; everything else must agree exactly.
    """
    from scipy.ndimage import binary_erosion

    shape = Shape("box", [box((0, 0, 0), (1.0, 0.6, 0.37))])
    out = make_sample(shape, (0.0, 0.0, 0.0), target_res=32, input_factor=4)
    tgt, surf = out["target"], out["surface"]
    k_min = int(np.argmax(tgt.any(axis=(0, 1))))
    assert set(np.nonzero(surf)[2].tolist()) == {k_min}  # one depth layer, nearest to the camera
    assert not (surf & ~tgt).any()
    face = tgt[:, :, k_min]
    assert (binary_erosion(face) <= surf[:, :, k_min]).all()
    np.testing.assert_array_equal(out["input"], max_pool(surf, 4))
    assert out["input"].shape == (8, 8, 8)


def test_solid_occupancy_matches_brute_force_inside_test():
    """Separable per-primitive evaluation == testing every voxel centre against the union."""
    shape = make_shape("chair", np.random.default_rng(3))
    geom = ViewGeometry(shape, camera_rotation(40.0, 20.0, 5.0), res=24)
    idx = np.stack(np.meshgrid(*[np.arange(24)] * 3, indexing="ij"), -1).reshape(-1, 3)
    for pad in (0.0, 0.5):
        ref = shape.contains(geom.voxel_centres_to_object(idx), pad / geom.scale).reshape(24, 24, 24)
        got = solid_occupancy(shape, geom, pad=pad)
        assert (got != ref).sum() <= 2, pad  # float32 vs float64 ties on the boundary
        assert got.sum() > 50


@pytest.mark.parametrize("category", sorted(GENERATORS))
def test_visible_surface_lies_in_the_target(category):
    """The back-projected depth (before pooling) lies in the filled solid; the object fills the grid."""
    rng = np.random.default_rng(7)
    fracs = []
    for _ in range(2):
        shape = make_shape(category, rng)
        view = VIEW_SETS["same"][int(rng.integers(125))]
        out = make_sample(shape, view, target_res=48, input_factor=4)
        surf, tgt = out["surface"], out["target"]
        assert surf.sum() > 20 and tgt.sum() > surf.sum() * 0.5
        fracs.append((surf & tgt).sum() / surf.sum())
        # longest side spans the grid minus the margin
        extent = max(np.ptp(np.nonzero(tgt)[d]) + 1 for d in range(3))
        assert 45 <= extent <= 48
    assert min(fracs) > 0.93 and np.mean(fracs) > 0.95, fracs


def test_view_sets_are_disjoint_and_sized():
    assert len(VIEW_SETS["same"]) == 125 and len(VIEW_SETS["cross"]) == 216
    assert not set(VIEW_SETS["same"]) & set(VIEW_SETS["cross"])


# ---------------------------------------------------------------- datamodule
def test_batches_labels_and_categories(prepared):
    dm = prepared
    info = dm.describe()
    assert info["split_sizes"] == SMALL
    assert set(info["counts"]["train"]) == set(SEEN_CATEGORIES)
    assert set(info["counts"]["test_unseen"]) == set(UNSEEN_CATEGORIES)
    assert info["input_shape"] == [1, 8, 8, 8] and info["target_shape"] == [1, 32, 32, 32]
    assert info["bytes_on_disk"] > 0 and len(info["manifest_hash"]) == 64
    assert dm.test_split_names == ["test_same", "test_cross", "test_unseen"]
    batch = next(iter(dm.train_dataloader()))
    assert batch["input"].shape == (4, 1, 8, 8, 8) and batch["input"].dtype == torch.float32
    assert batch["target"].shape == (4, 1, 32, 32, 32) and batch["target"].dtype == torch.float32
    assert set(torch.unique(batch["target"]).tolist()) <= {0.0, 1.0}
    assert batch["label"].dtype == torch.int64
    for lab, cat in zip(batch["label"].tolist(), batch["category"]):
        assert SEEN_CATEGORIES[lab] == cat
    loaders = dm.test_dataloader()
    assert len(loaders) == 3
    unseen = next(iter(loaders[2]))
    assert (unseen["label"] == -1).all() and unseen["split"][0] == "test_unseen"
    # pooled input of a sample is inside the pooled target (mostly)
    x, y = batch["input"], torch.nn.functional.max_pool3d(batch["target"], 4)
    assert float((x * y).sum() / x.sum()) > 0.95


def test_splits_use_distinct_shapes_and_view_sets(prepared):
    items = prepared.manifest["items"]
    by = lambda s: {(i["category"], i["shape_group"], i["shape_index"]) for i in items if i["split"] == s}  # noqa: E731
    assert not by("train") & by("val") and not by("train") & by("test_same")
    assert by("test_same") == by("test_cross")  # same test shapes, other views (as test_125/test_216)
    views = lambda s: {tuple(i["view"]) for i in items if i["split"] == s}  # noqa: E731
    assert views("test_same") <= set(VIEW_SETS["same"]) and views("test_cross") <= set(VIEW_SETS["cross"])


def test_show_writes_png(prepared, tmp_path):
    from PIL import Image

    path = prepared.show(5, tmp_path / "s.png")
    img = Image.open(path)
    assert img.size[0] >= 4 * 32 and img.size[1] >= 5 * 32


def test_same_seed_same_bytes_other_seed_differs(prepared, tmp_path):
    again = small_dm(tmp_path / "b")
    again.prepare_data()
    again.setup()
    assert again.describe()["manifest_hash"] == prepared.describe()["manifest_hash"]
    assert contents(again) == contents(prepared)
    files = [it["file"] for it in prepared.manifest["items"]]
    assert all((again.data_dir / f).read_bytes() == (prepared.data_dir / f).read_bytes() for f in files[:5])
    other = small_dm(tmp_path / "c", seed=1)
    other.prepare_data()
    other.setup()
    assert other.describe()["manifest_hash"] != prepared.describe()["manifest_hash"]
    a, b = list(contents(other).values()), list(contents(prepared).values())
    assert len(a) == len(b) and sum(x != y for x, y in zip(a, b)) > len(a) // 2


def test_interrupted_preparation_resumes_identically(prepared, tmp_path, monkeypatch):
    ref = contents(prepared)
    dm = small_dm(tmp_path / "r")
    real = completion_sources.synth_pair
    calls = {"n": 0}

    def flaky(*args, **kwargs):
        calls["n"] += 1
        if calls["n"] == 10:
            raise KeyboardInterrupt  # killed mid-run
        return real(*args, **kwargs)

    monkeypatch.setattr(completion_sources, "synth_pair", flaky)
    with pytest.raises(KeyboardInterrupt):
        dm.prepare_data()
    assert not (dm.data_dir / MANIFEST).exists() and (dm.data_dir / MARKER).exists()
    assert len(list(dm.data_dir.rglob("*.npz"))) == 9
    with pytest.raises(DataError, match="no prepared data"):
        dm.setup()
    # a half-written temp file and a deleted item, as after a hard kill
    (dm.data_dir / "items" / "train" / ".x.npz.abc.tmp").write_bytes(b"partial")
    monkeypatch.setattr(completion_sources, "synth_pair", real)
    calls["n"] = 0
    dm.prepare_data()
    dm.setup()
    assert contents(dm) == ref
    assert dm.describe()["manifest_hash"] == prepared.describe()["manifest_hash"]
    assert not list(dm.data_dir.rglob("*.tmp"))
    # deleting the manifest and one item: only that item is regenerated
    (dm.data_dir / MANIFEST).unlink()
    victim = dm.data_dir / prepared.manifest["items"][3]["file"]
    victim.unlink()
    counter = {"n": 0}

    def counting(*a, **k):
        counter["n"] += 1
        return real(*a, **k)

    monkeypatch.setattr(completion_sources, "synth_pair", counting)
    dm.prepare_data()
    assert counter["n"] == 1 and contents(dm) == ref


def test_config_change_is_refused_and_rebuild_replaces_without_mixing(prepared, tmp_path):
    """Another config's folder is refused with one line naming what differs and
    nothing is deleted; only request_rebuild() (``lit3d-data --rebuild``) replaces it."""
    dm = small_dm(tmp_path / "m", seed=1)
    dm.prepare_data()
    before = contents(dm)
    dm0 = small_dm(tmp_path / "m", seed=0)  # same folder, other config
    with pytest.raises(DataError, match=r"m: holds data prepared with another config \(seed: 0 here, 1 there\); "
                                        r"nothing was deleted.*--rebuild"):
        dm0.prepare_data()
    dm.setup()
    assert contents(dm) == before  # the other config's items are untouched
    from datamodules.cache import request_rebuild

    request_rebuild()
    try:
        dm0.prepare_data()
    finally:
        request_rebuild(False)
    dm0.setup()
    assert contents(dm0) == contents(prepared)
    assert dm0.describe()["manifest_hash"] == prepared.describe()["manifest_hash"]


def test_corrupt_cached_item_names_the_file(tmp_path):
    p = tmp_path / "x.npz"
    save_pair(p, np.ones((2, 2, 2), bool), np.zeros((4, 4, 4), bool))
    a, b = load_pair(p)
    assert a.sum() == 8 and b.sum() == 0 and b.shape == (4, 4, 4)
    p.write_bytes(p.read_bytes()[:40])
    with pytest.raises(DataError, match="x.npz"):
        load_pair(p)


def test_recgan_without_root_says_how_to_fix(tmp_path):
    dm = CompletionDataModule(target_res=64, source="recgan", data_dir=str(tmp_path), root=None, prepare={"progress": False})
    with pytest.raises(DataError, match=r"data\.root=PATH"):
        dm.prepare_data()
    with pytest.raises(DataError, match="source"):
        CompletionDataModule(target_res=64, source="shapnet", data_dir=str(tmp_path))


def test_categories_are_the_one_list_and_are_checked(tmp_path):
    # every category has a synthetic generator, and only those
    assert set(GENERATORS) == set(SEEN_CATEGORIES) | set(UNSEEN_CATEGORIES)
    dm = CompletionDataModule(target_res=64, data_dir=str(tmp_path), prepare={"progress": False})  # null: all of them
    assert dm.categories == SEEN_CATEGORIES and dm.unseen_categories == UNSEEN_CATEGORIES
    assert CompletionDataModule(target_res=64, data_dir=str(tmp_path), categories={"seen": ["chair"]}).categories == ("chair",)
    with pytest.raises(DataError, match=r"data\.categories\.seen: unknown categories \['chiar'\]"):
        CompletionDataModule(target_res=64, data_dir=str(tmp_path), categories={"seen": ["chiar"]})
    with pytest.raises(DataError, match=r"data\.categories\.unseen: unknown categories \['chair'\]"):
        CompletionDataModule(target_res=64, data_dir=str(tmp_path), categories={"unseen": ["chair"]})


@pytest.mark.parametrize("res,factor", [(32, 2), (32, 4), (64, 8), (64, 16), (48, 3), (48, 12)])
def test_max_pool_matches_torch(res, factor):
    from datamodules.completion.voxel_cache import max_pool_bool

    g = np.random.default_rng(res + factor).random((res, res, res)) < 0.01
    ref = torch.nn.functional.max_pool3d(torch.from_numpy(g.astype(np.float32))[None, None], factor)[0, 0] > 0
    np.testing.assert_array_equal(max_pool_bool(g, factor), ref.numpy())


def test_the_task_names_the_data_test_splits():
    """One list of test splits: the task's metric keys are the data's test splits without ``test_``."""
    from datamodules.completion.voxel_cache import TEST_SPLITS
    from lit3d.completion.module import TEST_SPLIT_KEYS

    assert TEST_SPLIT_KEYS == tuple(s.removeprefix("test_") for s in TEST_SPLITS)
