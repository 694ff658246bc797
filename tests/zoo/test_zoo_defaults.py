"""Slim zoo files and the defaults that use them: ``lit3d-reconstruct IMAGE`` with no ``--ckpt`` completes with
``completion-furniture``, ``--canonical`` with no value uses ``canonical-people``, and a slim (fp16, training-only parts left out)
copy of a checkpoint predicts what the checkpoint predicts. The zoo entries are pointed at untrained
checkpoints here, so the tests hold whether or not the trained files are installed."""
from __future__ import annotations

import numpy as np
import pytest
import torch

import lit3d.zoo as zoo
from lit3d.api.checkpoints import untrained_checkpoint
from lit3d.reconstruct.pipeline import load_completer
from lit3d.utils.checkpoints import META_KEY, load_checkpoint
from lit3d.zoo.slim import slim_checkpoint


@pytest.fixture(scope="module")
def completion_ckpts(tmp_path_factory):
    root = tmp_path_factory.mktemp("zoo_defaults")
    full = untrained_checkpoint("completion_demo", root / "full.ckpt", ["task.nets.k=10"])
    slim = root / "slim.pt"
    info = slim_checkpoint(full, slim, drop_prefixes=("classifier.",))
    return full, slim, info


def test_slim_copy_is_smaller_half_and_predicts_the_same(completion_ckpts):
    full, slim, info = completion_ckpts
    assert info["half"] and info["dropped_tensors"] > 0 and info["bytes"] < 0.55 * full.stat().st_size
    ck = load_checkpoint(slim)
    assert ck[META_KEY]["slim"]["dropped"] == ["classifier."]
    assert not any(k.startswith("classifier.") for k in ck["state_dict"])
    big = [v for v in ck["state_dict"].values() if v.is_floating_point() and v.numel() >= 1024]
    assert big and all(v.dtype == torch.float16 for v in big)
    a, b = load_completer(full), load_completer(slim)
    assert b.threshold == a.threshold and b.geometry.as_dict() == a.geometry.as_dict()
    r = a.geometry.input_res
    rng = np.random.default_rng(0)
    partial = np.zeros((r, r, r), bool)
    partial[r // 4: 3 * r // 4, r // 4: 3 * r // 4, : r // 2] = rng.random((r // 2, r // 2, r // 2)) < 0.5
    pa, pb = a.probabilities(partial), b.probabilities(partial)
    # fp16 weights: ~3 significant digits each; the probabilities agree to about 1e-2, the decisions almost all
    assert np.abs(pa - pb).max() < 2e-2
    assert ((pa > a.threshold) == (pb > b.threshold)).mean() > 0.999


def test_slim_refuses_to_replace_its_source(completion_ckpts):
    full, _, _ = completion_ckpts
    with pytest.raises(ValueError, match="its own checkpoint"):
        slim_checkpoint(full, full)


def test_resolve_zoo_name_or_file(tmp_path, monkeypatch, completion_ckpts):
    _, slim, _ = completion_ckpts
    monkeypatch.setitem(zoo.ZOO, "completion-furniture",
                        zoo.ZooModel("completion-furniture", "completion", str(slim), "test", "test", "test"))
    path, label = zoo.resolve("completion-furniture")
    assert path == slim and label.startswith("shipped completion-furniture")
    own = tmp_path / "completion-furniture"  # a file of the same name wins over the zoo
    own.write_bytes(b"x")
    monkeypatch.chdir(tmp_path)
    assert zoo.resolve("completion-furniture") == (own.relative_to(tmp_path), "completion-furniture")
    with pytest.raises(zoo.ZooError, match="not in this installation"):
        monkeypatch.setitem(zoo.ZOO, "canonical-people",
                            zoo.ZooModel("canonical-people", "canonical", "zoo/none.pt", "t", "remake it", "t"))
        zoo.resolve("canonical-people")


def test_reconstruct_without_ckpt_uses_the_zoo_completion_model(tmp_path, monkeypatch, capsys, completion_ckpts):
    from PIL import Image

    from lit3d.cli.reconstruct import main
    from lit3d.reconstruct.backproject import RECGAN_FOV_DEG, Intrinsics
    from lit3d.reconstruct.synthetic import pose_in_front, render_depth_pinhole
    from datamodules.completion.furniture import make_shape, shape_mesh

    _, slim, _ = completion_ckpts
    monkeypatch.setitem(zoo.ZOO, "completion-furniture",
                        zoo.ZooModel("completion-furniture", "completion", str(slim), "test", "test", "test"))
    mesh = pose_in_front(shape_mesh(make_shape("chair", np.random.default_rng(3))), azimuth=40.0, elevation=25.0)
    depth = render_depth_pinhole(mesh, Intrinsics.from_fov(RECGAN_FOV_DEG, 160, 120), 160, 120)
    Image.fromarray(np.round(depth * 1000).astype(np.uint16)).save(tmp_path / "chair.png")
    out = tmp_path / "out"
    assert main([str(tmp_path / "chair.png"), "--out", str(out), "--size", "96"]) == 0
    err = capsys.readouterr().err
    assert "completion model: shipped completion-furniture" in err
    assert {p.name for p in out.iterdir()} == {"chair.json", "chair.obj", "chair.png", "chair_occupancy.npz"}


def test_canonical_flag_without_value_names_the_zoo_model():
    from lit3d.cli.reconstruct import ZOO_CANONICAL, _parser

    args = _parser().parse_args(["d.png", "--out", "o", "--canonical"])
    assert args.canonical == ZOO_CANONICAL and args.ckpt is None
    args = _parser().parse_args(["d.png", "--out", "o", "--canonical", "my.ckpt"])
    assert args.canonical == "my.ckpt"
    path, label = zoo.resolve(ZOO_CANONICAL)
    assert path == zoo.zoo_model(ZOO_CANONICAL).path and label.startswith("shipped canonical-people")
