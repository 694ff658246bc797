"""Completion data from a mesh folder of your own (``data.source=meshes``): every category folder is
read, names outside the thesis's ten become user categories with their own class labels, a category
with fewer than ``data.meshes.min_models`` models uses its models with a console line (never procedural
shapes in its place), and ``lit3d-data`` / ``lit3d-train`` run on it."""
from __future__ import annotations

import json
import logging
import sys

import pytest
import trimesh

from datamodules.completion import CompletionDataModule
from datamodules.completion.plan import DataConfigError

SIZES = {"train": 8, "val": 2, "test_same": 2, "test_cross": 2, "test_unseen": 2}


def write_folder(root):
    """3 meshes in ``animal/`` (a user category), 2 in ``chair/`` (a thesis one): small trimesh primitives."""
    shapes = {"animal": [trimesh.creation.icosphere(2), trimesh.creation.capsule(1.0, 0.4),
                         trimesh.creation.cylinder(0.4, 1.2)],
              "chair": [trimesh.creation.box((0.8, 1.2, 0.8)), trimesh.creation.box((1.0, 1.0, 0.6))]}
    for cat, meshes in shapes.items():
        (root / cat).mkdir(parents=True)
        for i, m in enumerate(meshes):
            m.export(root / cat / f"{cat}_{i}.obj")
    return root


def test_user_and_small_categories_are_read_not_swapped_for_procedural(tmp_path, caplog):
    root = write_folder(tmp_path / "models")
    dm = CompletionDataModule(source="meshes", root=str(root), data_dir=str(tmp_path / "cache"), target_res=32,
                              sizes=SIZES, prepare={"progress": False})
    assert dm.categories == ("animal", "chair") and dm.unseen_categories == () and dm.user_categories == ("animal",)
    assert dm.label_categories == ("bench", "chair", "couch", "table", "animal")
    with caplog.at_level(logging.WARNING, logger="lit3d.data"):
        dm.prepare_data()
    assert "category animal has 3 models (fewer than data.meshes.min_models=8): its own models are used" in caplog.text
    assert "category chair has 2 models" in caplog.text and "procedural" not in caplog.text
    m = json.loads((tmp_path / "cache" / "manifest.json").read_text())
    assert m["models_per_category"] == {"animal": 3, "chair": 2} and m["fallback"] == {} and m["dropped"] == []
    assert {it["category"] for it in m["items"]} == {"animal", "chair"}
    assert all(it["shape_source"] == "model" for it in m["items"])  # no procedural item queued
    assert m["seen_categories"] == list(dm.label_categories)
    dm.setup()
    batch = next(iter(dm.train_dataloader()))
    labels = dict(zip(batch["category"], batch["label"].tolist()))
    assert labels.get("animal", 4) == 4 and labels.get("chair", 1) == 1
    # a user category made unseen by the key; a name that is no folder and no thesis category: one line
    dm2 = CompletionDataModule(source="meshes", root=str(root), data_dir=str(tmp_path / "c2"), target_res=32,
                               sizes=SIZES, categories={"unseen": ["animal"]}, prepare={"progress": False})
    assert dm2.categories == ("chair",) and dm2.unseen_categories == ("animal",)
    with pytest.raises(DataConfigError, match=r"data.categories.seen: \['animl'\] are neither.*animal, chair"):
        CompletionDataModule(source="meshes", root=str(root), target_res=32, categories={"seen": ["animl"]})


def test_lit3d_data_shows_and_lit3d_train_trains_on_own_categories(tmp_path, monkeypatch, capsys, compose_cfg):
    from lit3d.cli.train import train

    root = write_folder(tmp_path / "models")
    args = ["experiment=completion_demo", "data.source=meshes", f"data.root={root}",
            "data.sizes={train:8,val:4,test_same:2,test_cross:2,test_unseen:0}", "data.batch_size=4",
            "data.prepare.progress=false"]
    monkeypatch.setattr(sys, "argv", ["lit3d-data", *args, f"paths.data_dir={tmp_path / 'data'}",
                                      f"hydra.run.dir={tmp_path / 'prep'}", "--show", "2"])
    import lit3d.cli.data

    lit3d.cli.data.main()
    out = capsys.readouterr().out
    info = json.loads(out[out.index("{"):out.rindex("}") + 1])
    assert info["models_per_category"] == {"animal": 3, "chair": 2} and info["user_categories"] == ["animal"]
    assert set(info["small_categories"]) == {"animal", "chair"} and set(info["counts"]["train"]) == {"animal", "chair"}
    assert (tmp_path / "prep" / "completion_samples.png").stat().st_size > 0
    # the classifier needs one class per label category: one line naming the key
    cfg = compose_cfg([*args, "debug=fdr", "callbacks.progress_bar=null"], data_dir=tmp_path / "data")
    with pytest.raises(ValueError, match=r"set task.nets.n_classes=5"):
        train(cfg)
    cfg = compose_cfg([*args, "debug=fdr", "callbacks.progress_bar=null", "task.nets.n_classes=5"],
                      data_dir=tmp_path / "data")
    train(cfg)
    metrics = json.loads((tmp_path / "run" / "metrics.json").read_text())
    assert any("/animal" in k for k in metrics), sorted(metrics)[:20]
