"""Images and meshes reach the W&B and TensorBoard loggers (recognised by class), and no other;
the completion task's validation previews (panels, marching-cubes meshes) follow their epochs."""
from __future__ import annotations

import numpy as np
import pytest
import torch
import trimesh
from PIL import Image

from lit3d.completion import previews
from lit3d.utils.log_images import log_image, log_mesh, logger_kind, media_loggers, obj_text


class _Recorder:
    def __init__(self):
        self.calls = []


class WandbLogger(_Recorder):  # the names Lightning's classes have
    def log_image(self, **kwargs):
        self.calls.append(("log_image", kwargs))

    def log_metrics(self, metrics, step=None):
        self.calls.append(("log_metrics", metrics, step))


class TensorBoardLogger(_Recorder):
    def __init__(self):
        super().__init__()
        self.experiment = self

    def add_image(self, tag, img, global_step=None, dataformats="CHW"):
        self.calls.append(("add_image", tag, img, global_step, dataformats))

    def add_mesh(self, tag, vertices, faces=None, global_step=None):
        self.calls.append(("add_mesh", tag, vertices, faces, global_step))


class CSVLogger(_Recorder):
    def log_image(self, **kwargs):  # pragma: no cover - must never be called
        raise AssertionError("a CSV logger takes no images")


class MyWandb(WandbLogger):
    """A user's subclass is still a W&B logger."""


def test_kinds_by_class_and_base_class():
    wb, tb, csv, sub = WandbLogger(), TensorBoardLogger(), CSVLogger(), MyWandb()
    assert [logger_kind(x) for x in (wb, tb, csv, sub, object())] == ["wandb", "tensorboard", None, "wandb", None]
    assert media_loggers([csv, wb, tb, sub]) == [wb, tb, sub]
    assert media_loggers(None) == []


def test_image_goes_to_wandb_and_tensorboard_only():
    wb, tb, csv = WandbLogger(), TensorBoardLogger(), CSVLogger()
    image = Image.new("RGBA", (40, 30), (255, 0, 0, 255))
    assert log_image([wb, csv, tb], "val/panels", image, 7, caption="input | prediction") == 2
    (name, kwargs), = wb.calls
    assert name == "log_image" and kwargs["key"] == "val/panels" and kwargs["images"] == [image]
    assert kwargs["step"] == 7 and kwargs["caption"] == ["input | prediction"]
    (name, tag, array, step, fmt), = tb.calls
    assert (name, tag, step, fmt) == ("add_image", "val/panels", 7, "HWC")
    assert array.shape == (30, 40, 3) and array.dtype == np.uint8 and (array[..., 0] == 255).all()
    assert log_image([CSVLogger()], "k", image, 0) == 0
    # arrays too (the canonical panels are (H, W, 3) arrays): grey (H, W) becomes 3 channels
    tb = TensorBoardLogger()
    log_image([tb], "grey", np.full((5, 6), 0.5, np.float32), 1)
    assert tb.calls[0][2].shape == (5, 6, 3) and tb.calls[0][2].dtype == np.float32
    with pytest.raises(ValueError, match="expected an"):
        log_image([tb], "bad", np.zeros((2, 3, 4, 5)), 1)


def test_mesh_goes_to_wandb_as_object3d_and_tensorboard_as_mesh():
    import wandb

    wb, tb = WandbLogger(), TensorBoardLogger()
    sphere = trimesh.creation.icosphere(1)
    assert log_mesh([wb, CSVLogger(), tb], "val/mesh/prediction", sphere.vertices, sphere.faces, 3) == 2
    (name, metrics, step), = wb.calls
    assert name == "log_metrics" and step == 3 and isinstance(metrics["val/mesh/prediction"], wandb.Object3D)
    (name, tag, verts, faces, step), = tb.calls
    assert (name, tag, step) == ("add_mesh", "val/mesh/prediction", 3)
    assert verts.shape == (1, len(sphere.vertices), 3) and faces.shape == (1, len(sphere.faces), 3)
    with pytest.raises(ValueError, match="expected vertices"):
        log_mesh([tb], "k", np.zeros((4, 2)), sphere.faces, 0)


def test_obj_text_round_trips_through_trimesh(tmp_path):
    sphere = trimesh.creation.icosphere(1)
    (tmp_path / "s.obj").write_text(obj_text(sphere.vertices, sphere.faces))
    back = trimesh.load(tmp_path / "s.obj", process=False)
    assert np.allclose(back.vertices, sphere.vertices, atol=1e-5) and (back.faces == sphere.faces).all()


# ------------------------------------------------------------------ completion previews
class _HParams(dict):  # Lightning's AttributeDict: keys as attributes too
    __getattr__ = dict.__getitem__


class _Trainer:
    def __init__(self, sanity_checking: bool):
        self.is_global_zero, self.sanity_checking = True, sanity_checking


class _FakeCompletion:
    """Just what the previews read of a CompletionTask: a ball of radius 10 voxels at 32^3."""

    def __init__(self, loggers, epoch, image_every=1, mesh_every=2, sanity_checking=False):
        self.loggers, self.current_epoch, self.global_step = loggers, epoch, 10 * epoch + 1
        self.panels = _HParams(image_every_n_epochs=image_every, mesh_every_n_epochs=mesh_every)
        self.trainer, self.device, self.threshold = _Trainer(sanity_checking), torch.device("cpu"), torch.tensor(0.5)

    def __call__(self, partial):  # (B, 1, r, r, r) -> (B, 1, R, R, R)
        return _ball(32)[None, None].expand(partial.shape[0], 1, -1, -1, -1)


def _ball(res: int, radius: float = 10.0) -> torch.Tensor:
    x = torch.arange(res, dtype=torch.float32) - (res - 1) / 2
    return ((x[:, None, None] ** 2 + x[None, :, None] ** 2 + x[None, None, :] ** 2) <= radius**2).float()


def _batch():
    return {"input": torch.zeros(2, 1, 8, 8, 8), "target": _ball(32)[None, None].repeat(2, 1, 1, 1, 1),
            "category": ["chair", "table"]}


def _previews(monkeypatch, epoch, **kw):
    tb = TensorBoardLogger()
    task = _FakeCompletion([CSVLogger(), tb], epoch, **kw)
    monkeypatch.setattr(previews, "split_figure", lambda *a, **k: Image.new("RGB", (16, 16)))
    previews.log_validation_previews(task, _batch())
    return [c[1] for c in tb.calls], tb


@pytest.mark.parametrize("epoch, mesh_every, expected", [
    (0, 2, ["val/panels", "val/mesh/prediction", "val/mesh/target"]),
    (1, 2, ["val/panels"]),
    (4, 2, ["val/panels", "val/mesh/prediction", "val/mesh/target"]),
    (4, 0, ["val/panels"]),  # 0: never
])
def test_completion_previews_follow_their_epochs(monkeypatch, epoch, mesh_every, expected):
    tags, _ = _previews(monkeypatch, epoch, mesh_every=mesh_every)
    assert tags == expected


def test_completion_meshes_share_one_frame_and_match_the_grid(monkeypatch):
    _, tb = _previews(monkeypatch, 0)
    meshes = {c[1]: (c[2][0], c[3][0]) for c in tb.calls if c[0] == "add_mesh"}
    pred_v, pred_f = meshes["val/mesh/prediction"]
    target_v, _ = meshes["val/mesh/target"]
    # the prediction is the target's ball: same surface; centred in [-0.5, 0.5]^3, radius about 10/32
    assert np.allclose(pred_v, target_v) and len(pred_f) > 100
    radius = np.linalg.norm(pred_v, axis=1)
    assert abs(radius.mean() - 10 / 32) < 0.02 and np.abs(pred_v.mean(0)).max() < 0.01


def test_no_media_logger_renders_nothing(monkeypatch):
    task = _FakeCompletion([CSVLogger()], 0)
    monkeypatch.setattr(previews, "split_figure", lambda *a, **k: pytest.fail("rendered without a logger"))
    previews.log_validation_previews(task, _batch())


def test_no_meshes_during_the_sanity_check(monkeypatch):
    tags, _ = _previews(monkeypatch, 0, sanity_checking=True)
    assert tags == ["val/panels"]


def test_fine_grids_are_pooled_for_the_preview(monkeypatch):
    args = (_FakeCompletion([], 0), torch.zeros(1, 8, 8, 8), _ball(32)[None])
    full, _ = previews.sample_meshes(*args)["prediction"]
    monkeypatch.setattr(previews, "PREVIEW_RES", 16)  # the 32^3 ball meshed at 16^3: same place and size
    pooled, _ = previews.sample_meshes(*args)["prediction"]
    assert len(pooled) < len(full) / 3
    assert abs(np.linalg.norm(pooled, axis=1).mean() - 10 / 32) < 0.03 and np.abs(pooled.mean(0)).max() < 0.01
