"""The Python API (lit3d.api): a cheap ``import lit3d``, loading any task, one-line errors, and the
TorchScript export giving the eager outputs. The worked examples are docs/api.md's doctests
(tests/api/test_api_docs.py)."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys

import numpy as np
import pytest
import torch

import lit3d
from lit3d.api import InputError, checkpoint_task, export, load, untrained_checkpoint
from lit3d.api.export import exportable
from lit3d.reconstruct.canonical import CanonicalMapper
from lit3d.reconstruct.pipeline import Completer

pytestmark = pytest.mark.usefixtures("one_torch_thread")

QUALITY_FEATURES = ["task.features=[mask_ssim/ceramic_lightbulb/flat,chamfer]"]
CHECKPOINTS = {  # name -> (experiment, overrides): untrained models at the tiny configs' sizes
    "completion": ("completion_demo", []),
    "canonical": ("canonical_tiny", []),
    "canonical_redraw": ("canonical_tiny", ["task.net.head.kind=redraw"]),
    "quality": ("quality_demo", QUALITY_FEATURES),
}


@pytest.fixture(scope="module")
def ckpts(tmp_path_factory) -> dict:
    root = tmp_path_factory.mktemp("api_ckpts")
    torch.manual_seed(0)  # the same random weights every run
    return {name: untrained_checkpoint(exp, root / f"{name}.ckpt", ov) for name, (exp, ov) in CHECKPOINTS.items()}


def test_import_lit3d_is_cheap_and_has_a_version():
    code = ("import sys, lit3d; v = lit3d.__version__; "
            "print(v, sorted(m for m in ('torch', 'lightning', 'hydra') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    version, heavy = out.stdout.split(" ", 1)
    from importlib.metadata import version as dist_version

    assert version == dist_version("lit3d") and heavy.strip() == "[]"


def test_lazy_names_are_the_api():
    import lit3d.api

    assert sorted(lit3d.API) == sorted(lit3d.api.__all__)
    assert lit3d.load is lit3d.api.load and "complete" in dir(lit3d)
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        lit3d.nope


def test_load_gives_each_task_its_model(ckpts):
    assert isinstance(load(ckpts["completion"]), Completer)
    mapper = load(ckpts["canonical"])
    assert isinstance(mapper, CanonicalMapper) and mapper.image_size == 48
    quality = load(ckpts["quality"])
    assert quality.features == ["mask_ssim/ceramic_lightbulb/flat", "chamfer"]
    assert [checkpoint_task(ckpts[k]) for k in ("completion", "canonical", "quality")] == [
        "completion", "canonical", "quality"]


def test_bad_checkpoints_are_one_line(ckpts, tmp_path):
    torch.save({"state_dict": {}}, tmp_path / "plain.ckpt")
    torch.save({"state_dict": {}, "lit3d": {"task": {"name": "segmentation"}}}, tmp_path / "other.ckpt")
    (tmp_path / "notes.ckpt").write_text("not a checkpoint\n")
    os.mkfifo(tmp_path / "pipe.ckpt")  # named for what it is (it was "checkpoint not found"), never opened
    (tmp_path / "folder.ckpt").mkdir()
    cases = {tmp_path / "missing.ckpt": "checkpoint not found", tmp_path / "notes.ckpt": "not a readable checkpoint",
             tmp_path / "pipe.ckpt": "a named pipe (FIFO), not a regular checkpoint",
             tmp_path / "folder.ckpt": "a folder, not a checkpoint",
             tmp_path / "plain.ckpt": "not a lit3d checkpoint",
             tmp_path / "other.ckpt": "checkpoint of task 'segmentation', which lit3d.load does not know"}
    for path, message in cases.items():
        with pytest.raises(InputError) as info:
            load(path)
        text = str(info.value)
        assert text.startswith(str(path)) and message in text and "\n" not in text, text


def test_wrong_model_or_array_is_one_line(ckpts):
    completer, mapper = load(ckpts["completion"]), load(ckpts["canonical"])
    cases = [
        (lambda: lit3d.complete(np.zeros((4, 4, 4)), completer), "depth: expected an array of shape (N x N), got (4, 4, 4)"),
        (lambda: lit3d.complete(np.full((8, 8), np.nan), completer), "depth: 64 depth pixels are NaN"),
        (lambda: lit3d.complete_grid(np.zeros((16, 16)), completer), "partial: expected an array of shape (16 x 16 x 16)"),
        (lambda: lit3d.complete(np.ones((8, 8)), mapper), "complete: needs a completion model"),
        (lambda: lit3d.canonical_form(np.ones((32, 32)), mapper), "depth: expected an array of shape (48 x 48), got (32, 32)"),
        (lambda: lit3d.canonical_points(np.zeros((8, 8)), mapper), "depth: all background (every depth pixel is 0)"),
        (lambda: lit3d.score("a.obj", "b.obj", completer), "score: needs a quality model"),
        (lambda: export(load(ckpts["quality"]), "x.pt"), "export: needs a completion or canonical model"),
    ]
    for call, message in cases:
        with pytest.raises(InputError) as info:
            call()
        assert message in str(info.value) and "\n" not in str(info.value), str(info.value)


def test_canonical_points_sit_where_the_subject_was(ckpts):
    """A camera depth image -> canonical-pose points in the camera frame, placed at the visible
    points' bounding box (lit3d-reconstruct --canonical's first step)."""
    import trimesh

    from lit3d.reconstruct.backproject import backproject
    from lit3d.reconstruct.synthetic import pose_in_front, render_depth_pinhole

    camera = lit3d.Intrinsics.from_fov(lit3d.RECGAN_FOV_DEG, 160, 120)
    depth = render_depth_pinhole(pose_in_front(trimesh.creation.capsule(), distance=1.5), camera, 160, 120)
    visible = backproject(depth, camera)
    points = lit3d.canonical_points(depth, load(ckpts["canonical"]), camera)
    assert points.ndim == 2 and points.shape[1] == 3 and len(points) >= 10
    lo, hi = visible.min(0), visible.max(0)
    margin = 0.1 * float((hi - lo).max())  # the canonical image may reach the ortho frame's edge (0.55 of 0.5)
    assert np.all(points[:, :2] >= lo[:2] - margin) and np.all(points[:, :2] <= hi[:2] + margin)
    assert 1.0 < float(points[:, 2].mean()) < 2.0  # metres in front of the camera, near the subject


@pytest.mark.parametrize("name", ["completion", "canonical", "canonical_redraw"])
def test_exported_net_gives_the_eager_outputs(name, ckpts, tmp_path):
    """TorchScript of the generator / canonical net against the eager module, within 1e-5, on random
    inputs other than those it was traced on and at other batch sizes."""
    model = load(ckpts[name])
    path = export(model, tmp_path / "net.pt")
    traced = torch.jit.load(path)
    eager, _ = exportable(model)
    for batch, seed in ((1, 11), (3, 12)):
        _, inputs = exportable(model, batch=batch, seed=seed)
        with torch.no_grad():
            want, got = eager(*inputs), traced(*inputs)
        want, got = (want, got) if isinstance(want, tuple) else ((want,), (got,))
        for w, g in zip(want, got, strict=True):
            assert g.shape == w.shape and g.shape[0] == batch
            assert float((g - w).abs().max()) <= 1e-5
    if isinstance(model, Completer):  # and the eager path the API itself runs
        grid = inputs[0][0, 0].numpy() > 0
        with torch.no_grad():
            ts = traced(torch.from_numpy(grid).float()[None, None])[0, 0].numpy()
        assert np.abs(ts - lit3d.complete_grid(grid, model)).max() <= 1e-5


def test_export_never_writes_over_a_checkpoint(ckpts, tmp_path):
    """``export(load(p), p)`` once replaced the checkpoint with TorchScript. Now: its own checkpoint (also
    through a link), any other checkpoint and a folder are refused with one line naming the file, before
    anything is written; an earlier export is replaced through a temp file and a rename."""
    from lit3d.utils.io import OutputError

    own, other = tmp_path / "own.ckpt", tmp_path / "other.ckpt"
    shutil.copy(ckpts["completion"], own)
    shutil.copy(ckpts["canonical"], other)
    (tmp_path / "link.pt").symlink_to(own)
    (tmp_path / "folder.pt").mkdir()
    before = {p: p.read_bytes() for p in (own, other)}
    model = load(own)
    cases = {own: f"{own}: the output would replace the input {own} (choose another output file)",
             tmp_path / "link.pt": f"{tmp_path / 'link.pt'}: the output would replace the input {own}",
             other: f"{other}: is a checkpoint (a torch.save archive); export writes TorchScript and never replaces",
             tmp_path / "folder.pt": f"{tmp_path / 'folder.pt'}: an output file of this name exists as a folder"}
    for out, message in cases.items():
        with pytest.raises(OutputError) as info:
            export(model, out)
        assert str(info.value).startswith(message) and "\n" not in str(info.value), str(info.value)
    assert {p: p.read_bytes() for p in (own, other)} == before  # both checkpoints as they were
    assert torch.load(own, weights_only=True)["lit3d"]  # still a checkpoint, not TorchScript
    assert sorted(p.name for p in tmp_path.iterdir()) == ["folder.pt", "link.pt", "other.ckpt", "own.ckpt"]
    out = tmp_path / "net.pt"
    out.write_bytes(b"an earlier export")
    assert export(model, out) == out and torch.jit.load(out) is not None  # a non-checkpoint is replaced
    assert not list(tmp_path.glob(".*.tmp"))  # no temp file left


def _camera_depth():
    import trimesh

    from lit3d.reconstruct.synthetic import pose_in_front, render_depth_pinhole

    camera = lit3d.Intrinsics.from_fov(lit3d.RECGAN_FOV_DEG, 160, 120)
    return render_depth_pinhole(pose_in_front(trimesh.creation.box(), distance=1.5), camera, 160, 120), camera


def test_integer_depth_is_millimetres_in_the_api_as_in_the_cli(ckpts):
    """One rule for the CLI and the API: integer depth = millimetres (``depth_scale``), float = metres; a
    uint16 millimetre image was read as metres (1500 m away) by ``complete`` and ``canonical_points``."""
    completer, mapper = load(ckpts["completion"]), load(ckpts["canonical"])
    metres, camera = _camera_depth()
    millimetres = np.round(metres * 1000).astype(np.uint16)
    a, b = lit3d.complete(metres, completer, camera), lit3d.complete(millimetres, completer, camera)
    assert abs(float(a.points[:, 2].mean()) - float(b.points[:, 2].mean())) < 1e-3  # the same place, in metres
    assert 1.0 < float(b.points[:, 2].mean()) < 2.0
    no_reading = millimetres.copy()
    no_reading[0, :] = 65535  # the sensor's "no reading": background, as in lit3d-reconstruct
    assert len(lit3d.complete(no_reading, completer, camera).points) == len(b.points)
    cm = lit3d.complete(np.round(metres * 100).astype(np.int32), completer, camera, depth_scale=0.01)
    assert abs(float(cm.points[:, 2].mean()) - float(b.points[:, 2].mean())) < 0.01
    pa, pb = lit3d.canonical_points(metres, mapper, camera), lit3d.canonical_points(millimetres, mapper, camera)
    assert np.abs(pa.mean(0) - pb.mean(0)).max() < 0.01 and 1.0 < float(pb[:, 2].mean()) < 2.0


def test_the_api_checks_its_arguments_at_the_door(ckpts, tmp_path):
    """Each bad argument is one InputError line naming it (before: a bool mask taken as depth, AttributeError
    for a tuple camera or a dict of options, a probability grid silently thresholded at 0, an all-zero
    canonical image run through the net, size=0 taken as the default, a bad override failing in torch)."""
    completer, mapper = load(ckpts["completion"]), load(ckpts["canonical"])
    depth, camera = _camera_depth()
    s = mapper.image_size
    half = np.zeros((s, s), np.float32)
    half[s // 4: 3 * s // 4, s // 4: 3 * s // 4] = 0.5
    cases = [
        (lambda: lit3d.complete(depth > 0, completer), "depth: a bool array (a mask?) is not depth"),
        (lambda: lit3d.canonical_points(depth > 0, mapper), "depth: a bool array (a mask?) is not depth"),
        (lambda: lit3d.complete(np.full((4, 4), "x"), completer), "depth: expected a numeric array"),
        (lambda: lit3d.complete(-depth, completer), "depth: negative depth"),
        (lambda: lit3d.complete(depth, completer, (100.0, 100.0, 80.0, 60.0)),
         "intrinsics: expected lit3d.Intrinsics(fx, fy, cx, cy) in pixels (or None: the 3D-RecGAN++ camera), got tuple"),
        (lambda: lit3d.canonical_points(depth, mapper, {"fx": 100}), "intrinsics: expected lit3d.Intrinsics"),
        (lambda: lit3d.complete(depth, completer, camera, {"near": 1.0}),
         "options: expected lit3d.Options(mask=..., near=..., far=...), got dict"),
        (lambda: lit3d.complete(depth, completer, camera, lit3d.Options(mask=np.ones((4, 4), bool))),
         "options.mask: expected an array of shape (120 x 160), got (4, 4)"),
        (lambda: lit3d.complete(depth, completer, camera, lit3d.Options(near=2.0, far=1.0)),
         "options.near=2.0 >= options.far=1.0: empty depth range"),
        (lambda: lit3d.complete_grid(np.full((16, 16, 16), 0.4), completer),
         "partial: float64 values other than 0 and 1 (e.g. 0.4); expected a 0/1 (bool) grid"),
        (lambda: lit3d.canonical_form(np.zeros((s, s), np.float32), mapper), "depth: all background (every pixel is 0)"),
        (lambda: lit3d.canonical_form(half * 4, mapper), "depth: values in [0, 2]; expected normalised depth in [0, 1]"),
        (lambda: lit3d.canonical_form((half > 0).astype(np.uint16), mapper), "depth: a uint16 array; expected float"),
        (lambda: lit3d.canonical_form(half, mapper, mask=np.zeros((s, s), bool)), "mask: empty"),
        (lambda: lit3d.score("a.obj", "b.obj", size=0), "size=0: expected 16..4096 pixels"),
        (lambda: lit3d.score("a.obj", "b.obj", size=True), "size=True: expected 16..4096 pixels"),
        (lambda: untrained_checkpoint("completion_demo", tmp_path / "x.ckpt", ["task.nets.k=0"]),
         "task.nets.k=0: expected an integer >= 1"),
        (lambda: untrained_checkpoint("completion_demo", tmp_path / "x.ckpt", ["task.nets.kk=3"]),
         "Could not override 'task.nets.kk'"),
        (lambda: untrained_checkpoint("completion_demo", tmp_path / "x.ckpt", "task.nets.k=10"),
         "overrides: expected a list of 'key=value' strings"),
        (lambda: untrained_checkpoint("nope", tmp_path / "x.ckpt"), "experiment=nope: no such experiment config"),
    ]
    for call, message in cases:
        with pytest.raises(InputError) as info:
            call()
        assert str(info.value).startswith(message) and "\n" not in str(info.value), str(info.value)
    assert not (tmp_path / "x.ckpt").exists()
    ones = np.zeros((16, 16, 16), np.float32)
    ones[4:12, 4:12, 4:12] = 1.0  # a 0/1 float grid is a grid: the same as its bool
    assert np.array_equal(lit3d.complete_grid(ones, completer), lit3d.complete_grid(ones > 0, completer))
