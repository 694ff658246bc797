"""3D-RecGAN++ release reader: layouts, odd sizes, pairing by name, bad files, conversion."""
from __future__ import annotations

import os
import random
from pathlib import Path

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from datamodules.cache import DataError
from datamodules.completion import CompletionDataModule
from datamodules.completion.recgan import assign_splits, centre_fit, index_recgan, load_grid
from datamodules.completion.voxel_cache import load_pair
from tests.helpers.paths import SHARED_DATA

SHARED_SAMPLE = SHARED_DATA / "recgan_sample"
RAW = 32


def grids(shape: tuple[int, int, int], seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A random solid box blob (target) and its k-min face (input), both int8 (Dx, Dy, Dz, 1)."""
    rng = np.random.default_rng(seed)
    tgt = np.zeros(shape, np.int8)
    lo = [int(rng.integers(0, s // 3)) for s in shape]
    hi = [int(rng.integers(2 * s // 3, s)) for s in shape]
    tgt[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]] = 1
    inp = np.zeros_like(tgt)
    inp[:, :, lo[2]] = tgt[:, :, lo[2]]
    return inp[..., None], tgt[..., None]


def write(path: Path, arr: np.ndarray, key: str = "arr_0") -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(path, **{key: arr})


def make_release(root: Path, old_layout: bool = False, unseen: bool = True) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """A tiny release: 4 seen categories (+ car), shapes of odd sizes; returns name -> raw grids."""
    cats = [("02828884", "bench"), ("03001627", "chair"), ("04256520", "coach" if old_layout else "couch"),
            ("04379243", "table")]
    if unseen:
        cats.append(("02958343", "car"))
    folders = ["train", "test"] if old_layout else ["train_125", "test_125", "test_216"]
    sizes = [(RAW, 20, 17), (RAW + 1, 21, 13), (15, RAW + 2, 30), (RAW, RAW + 1, RAW)]
    truth = {}
    seed = 0
    for synset, cat in cats:
        for folder in folders:
            if cat == "car" and folder.startswith("train"):
                continue
            ids = ["aa11", "bb22", "cc33"] if folder.startswith("train") else ["dd44"]
            for sid in ids:
                for v in range(2):
                    seed += 1
                    shape = sizes[seed % len(sizes)]
                    inp, tgt = grids(shape, seed)
                    name = f"{sid}_0_{int(folder.endswith('216'))}_{v}.npz"
                    write(root / f"P1_{synset}_{cat}" / f"{folder}_25d_vox256" / name, inp)
                    write(root / f"P1_{synset}_{cat}" / f"{folder}_3d_vox256" / name, tgt)
                    truth[f"{cat}/{folder}/{name}"] = (inp[..., 0], tgt[..., 0])
    return truth


def reference(inp: np.ndarray, tgt: np.ndarray, target_res: int, input_res: int):
    """Independent pad/crop (numpy pad / slicing) + torch max-pool."""
    def fit(a):
        out = a
        for ax, n in enumerate(a.shape):
            if n < RAW:
                before = (RAW - n) // 2
                width = [(0, 0)] * 3
                width[ax] = (before, RAW - n - before)
                out = np.pad(out, width)
            elif n > RAW:
                s = (n - RAW) // 2
                out = np.take(out, np.arange(s, s + RAW), axis=ax)
        return out

    def pool(a, r):
        t = torch.from_numpy(fit(a).astype(np.float32))[None, None]
        return F.max_pool3d(t, RAW // r)[0, 0].numpy().astype(bool)

    return pool(inp, input_res), pool(tgt, target_res)


def dm_for(root: Path, data_dir: Path, **kw) -> CompletionDataModule:
    return CompletionDataModule(source="recgan", root=str(root), data_dir=str(data_dir), recgan={"raw_res": RAW},
                                target_res=kw.pop("target_res", RAW), input_factor=4, batch_size=2,
                                prepare={"progress": False, "skip_bad": kw.pop("skip_bad", False)}, **kw)


# ---------------------------------------------------------------- helpers
def test_centre_fit_pads_and_crops_centred():
    a = np.ones((30, 33, 34), bool)
    out = centre_fit(a, 32)
    assert out.shape == (32, 32, 32) and out.sum() == 30 * 32 * 32
    assert not out[0].any() and out[1].all() and out[30].all() and not out[31].any()


@pytest.mark.parametrize("old_layout", [False, True])
def test_convert_release_sizes_and_pairing(tmp_path, monkeypatch, old_layout):
    root = tmp_path / "raw"
    truth = make_release(root, old_layout=old_layout)
    # listing order must not matter: shuffle every directory listing
    real_iterdir = Path.iterdir

    def shuffled(self):
        entries = list(real_iterdir(self))
        random.Random(str(self)).shuffle(entries)
        return iter(entries)

    monkeypatch.setattr(Path, "iterdir", shuffled)
    dm = dm_for(root, tmp_path / "cache")
    dm.prepare_data()
    dm.setup()
    info = dm.describe()
    sizes = info["split_sizes"]
    # per seen category: 3 train ids x 2 views -> 1 val id (2 views) + 2 train ids (4 views)
    assert sizes["train"] == 4 * 4 and sizes["val"] == 4 * 2
    assert sizes["test_same"] == 4 * 2
    assert sizes.get("test_cross", 0) == (0 if old_layout else 4 * 2)
    assert sizes["test_unseen"] == 2 and sizes.get("test_unseen_cross", 0) == (0 if old_layout else 2)
    assert set(info["counts"]["train"]) == {"bench", "chair", "couch", "table"}
    assert info["counts"]["test_unseen"] == {"car": 2}
    folder_views = {}
    for it in dm.manifest["items"]:
        inp, tgt = load_pair(dm.data_dir / it["file"])
        assert inp.shape == (8, 8, 8) and tgt.shape == (RAW, RAW, RAW)
        src_cat = "coach" if (old_layout and it["category"] == "couch") else it["category"]
        raw_in, raw_tg = truth[f"{src_cat}/{it['source_folder']}/{it['shape_id']}_{it['view']}.npz"]
        ref_in, ref_tg = reference(raw_in, raw_tg, RAW, 8)
        np.testing.assert_array_equal(inp.astype(bool), ref_in, err_msg=it["name"])
        np.testing.assert_array_equal(tgt.astype(bool), ref_tg, err_msg=it["name"])
        folder_views.setdefault(it["split"], set()).add(it["view_set"])
    assert folder_views["test_same"] == {"same"}
    # val ids are whole shapes, never shared with train
    ids = {s: {(i["category"], i["shape_id"]) for i in dm.manifest["items"] if i["split"] == s} for s in ("train", "val")}
    assert not ids["train"] & ids["val"]
    batch = next(iter(dm.train_dataloader()))
    assert batch["input"].shape == (2, 1, 8, 8, 8) and batch["target"].shape == (2, 1, RAW, RAW, RAW)
    assert dm.test_split_names == (["test_same", "test_unseen"] if old_layout
                                   else ["test_same", "test_cross", "test_unseen", "test_unseen_cross"])


def test_target_pooled_to_configured_resolution(tmp_path):
    root = tmp_path / "raw"
    truth = make_release(root, unseen=False)
    dm = dm_for(root, tmp_path / "cache", target_res=16)  # input 4^3
    dm.prepare_data()
    dm.setup()
    it = dm.manifest["items"][0]
    inp, tgt = load_pair(dm.data_dir / it["file"])
    raw_in, raw_tg = truth[f"{it['category']}/{it['source_folder']}/{it['shape_id']}_{it['view']}.npz"]
    ref_in, ref_tg = reference(raw_in, raw_tg, 16, 4)
    np.testing.assert_array_equal(tgt.astype(bool), ref_tg)
    np.testing.assert_array_equal(inp.astype(bool), ref_in)


def test_split_assignment_is_deterministic_and_keeps_a_train_id(tmp_path):
    root = tmp_path / "raw"
    make_release(root, unseen=False)
    pairs, _ = index_recgan(root)
    a = [(s, p.name) for s, p in assign_splits(pairs, ["chair"], [], 0.5, seed=3)]
    b = [(s, p.name) for s, p in assign_splits(list(reversed(pairs)), ["chair"], [], 0.5, seed=3)]
    assert a == b
    assert {p.split("_")[0] for s, p in a} == {"chair"}  # other categories dropped
    assert any(s == "train" for s, _ in a) and any(s == "val" for s, _ in a)


# ---------------------------------------------------------------- bad files
def _break(root: Path, kind: str) -> Path:
    folder = root / "P1_03001627_chair"
    name = "aa11_0_0_0.npz"
    if kind == "missing_key":
        bad = folder / "train_125_3d_vox256" / name
        write(bad, np.zeros((RAW, 4, 4, 1), np.int8), key="voxels")
    elif kind == "ndim":
        bad = folder / "train_125_25d_vox256" / name
        write(bad, np.zeros((RAW, 4), np.int8))
    elif kind == "shape_mismatch":
        bad = folder / "train_125_25d_vox256" / name
        write(bad, np.zeros((RAW, 5, 5, 1), np.int8))
    elif kind == "unpaired":
        bad = folder / "train_125_25d_vox256" / "zz99_0_0_0.npz"
        write(bad, np.zeros((RAW, 4, 4, 1), np.int8))
    elif kind == "corrupt":
        bad = folder / "test_125_3d_vox256" / "dd44_0_0_1.npz"
        bad.write_bytes(b"not a zip")
    return bad


@pytest.mark.parametrize("kind,words", [("missing_key", "missing key 'arr_0'"), ("ndim", "expected (Dx, Dy, Dz, 1)"),
                                        ("shape_mismatch", "differs from its target"), ("unpaired", "unpaired"),
                                        ("corrupt", "unreadable")])
def test_bad_file_error_names_file_or_is_skipped(tmp_path, kind, words):
    root = tmp_path / "raw"
    make_release(root, unseen=False)
    bad = _break(root, kind)
    dm = dm_for(root, tmp_path / "cache")
    with pytest.raises(DataError) as exc:
        dm.prepare_data()
    msg = str(exc.value)
    assert str(bad) in msg and words in msg, msg
    assert not (tmp_path / "cache" / "manifest.json").exists()
    assert not list((tmp_path / "cache").rglob("*.tmp"))
    ok = dm_for(root, tmp_path / "cache2", skip_bad=True)
    ok.prepare_data()
    ok.setup()
    info = ok.describe()
    assert info["skipped_bad_files"] == 1
    good = 4 * 6 + 4 * 2 + 4 * 2  # train+val, test_same, test_cross pairs in the release
    assert sum(info["split_sizes"].values()) == good - (0 if kind == "unpaired" else 1)


def test_missing_root_and_empty_root(tmp_path):
    with pytest.raises(DataError, match="set data.root=PATH"):
        dm_for(tmp_path / "nope", tmp_path / "c").prepare_data()
    (tmp_path / "empty").mkdir()
    with pytest.raises(DataError, match="no category folders"):
        dm_for(tmp_path / "empty", tmp_path / "c").prepare_data()
    assert load_grid  # public helper


# ---------------------------------------------------------------- the real sample
@pytest.mark.skipif(not SHARED_SAMPLE.is_dir(), reason=f"real 3D-RecGAN++ sample not found at {SHARED_SAMPLE}")
def test_real_sample_converts_with_expected_counts(tmp_path):
    dm = CompletionDataModule(source="recgan", root=str(SHARED_SAMPLE), data_dir=str(tmp_path / "c"),
                              target_res=64, input_factor=4, prepare={"progress": False}, batch_size=4)
    dm.prepare_data()
    dm.setup()
    info = dm.describe()
    # 1 train shape id per category, 4 views: one view per category is held out as val
    assert info["counts"] == {
        "train": {c: 3 for c in ("bench", "chair", "couch", "table")},
        "val": {c: 1 for c in ("bench", "chair", "couch", "table")},
        "test_same": {c: 4 for c in ("bench", "chair", "couch", "table")},
        "test_cross": {c: 4 for c in ("bench", "chair", "couch", "table")},
    }
    assert dm.test_split_names == ["test_same", "test_cross"]
    batch = next(iter(dm.test_dataloader()[1]))
    assert batch["input"].shape == (4, 1, 16, 16, 16) and batch["target"].shape == (4, 1, 64, 64, 64)
    # the partial view is mostly inside the (pooled) complete shape
    x = batch["input"]
    y = F.max_pool3d(batch["target"], 4)
    assert float((x * y).sum() / x.sum()) > 0.9
    assert os.path.getsize(dm.data_dir / "manifest.json") > 0


def _pair(category, split_kind, view_set, shape_id, view="0_0_0"):
    from datamodules.completion.recgan import RecganPair

    folder = f"{split_kind}_{'125' if view_set == 'same' else '216'}"
    return RecganPair(category, "0", folder, split_kind, view_set, shape_id, view, Path("i"), Path("t"))


def test_val_folders_are_read_and_held_out_ids_leave_every_view_set():
    seen, unseen = ["chair", "table"], ["car"]
    pairs = [_pair("chair", "train", vs, i, v) for vs in ("same", "cross") for i in "abcdefghij" for v in ("0_0_0", "1_1_1")]
    pairs += [_pair("table", "train", "same", i) for i in "abc"] + [_pair("table", "val", "same", "z")]
    pairs += [_pair("car", "test", vs, "u") for vs in ("same", "cross")] + [_pair("car", "train", "same", "w")]
    out = assign_splits(pairs, seen, unseen, val_fraction=0.2, seed=3)
    split_of = {(p.category, p.view_set, p.shape_id, p.view): s for s, p in out}
    # chair (no val folder): whole ids held out, with both their view sets; no id in train and val
    val_ids = {p.shape_id for s, p in out if s == "val" and p.category == "chair"}
    train_ids = {p.shape_id for s, p in out if s == "train" and p.category == "chair"}
    assert len(val_ids) == 2 and not val_ids & train_ids
    assert {p.view_set for s, p in out if s == "val" and p.category == "chair"} == {"same", "cross"}
    # table has a val folder: it is the validation set, every train pair stays in train
    assert [p.shape_id for s, p in out if s == "val" and p.category == "table"] == ["z"]
    assert sorted(p.shape_id for s, p in out if s == "train" and p.category == "table") == ["a", "b", "c"]
    # unseen categories: test 125 -> test_unseen, test 216 -> test_unseen_cross; their train folder is unused
    assert split_of[("car", "same", "u", "0_0_0")] == "test_unseen"
    assert split_of[("car", "cross", "u", "0_0_0")] == "test_unseen_cross"
    assert ("car", "same", "w", "0_0_0") not in split_of


@pytest.mark.parametrize("folder,category", [("P1_02691156_airplane", "plane"), ("P1_04090263_rifle", "firearm"),
                                             ("P1_04090263_gun", "firearm"), ("P1_04256520_coach", "couch"),
                                             ("P1_04256520_sofa", "couch"), ("P1_03001627_chair", "chair")])
def test_category_folder_aliases(folder, category):
    from datamodules.completion.recgan import parse_category_folder

    assert parse_category_folder(folder) == (folder.split("_")[1], category)
