"""The closed-set recall row (task.arch=recall): a subject classifier that draws the recalled
subject's training canonical image; its templates come from the training data and live in the
checkpoint; bad settings are named."""
import lightning.pytorch as pl
import pytest
import torch

from tests.helpers.canonical import square_subjects
from datamodules.canonical import CanonicalDataModule
from lit3d.canonical.module import CanonicalTask
from lit3d.canonical.recall import SubjectRecallNet

SIZE, K = 32, 4


def _batch(n=16, classes=K, size=SIZE):
    """Subjects told apart by size (:func:`conftest.square_subjects`); subject k's canonical image: a
    centred disc of radius 4 + 2k at depth 0.2 + 0.15k."""
    depth, mask, idx = square_subjects(n, size, classes)
    yy, xx = torch.meshgrid(torch.arange(size), torch.arange(size), indexing="ij")
    r = ((yy - size / 2) ** 2 + (xx - size / 2) ** 2).sqrt()
    t_mask = torch.stack([(r < 4 + 2 * k).float() for k in range(classes)])[:, None]
    t_depth = t_mask * (0.2 + 0.15 * torch.arange(classes).float())[:, None, None, None]
    return {"depth": depth, "mask": mask, "subject_idx": idx,
            "canon_depth": t_depth[idx], "canon_mask": t_mask[idx]}, t_depth, t_mask


def _task(**kw):
    return CanonicalTask(net={"image_size": SIZE, "recall_channels": [8, 16], "init": "he"}, arch="recall",
                         mask_loss="bce", identity={"classes": K, "weight": 1.0},
                         phases={"use": False, "alpha": 1.0, "beta": 1.0}, **kw)


def test_recall_learns_the_subjects_and_draws_their_canonical_images():
    torch.manual_seed(0)
    task = _task()
    batch, t_depth, t_mask = _batch()
    task.net.set_templates(t_depth, t_mask)
    opt = torch.optim.Adam(task.parameters(), 1e-2)
    for _ in range(150):
        out = task.net(batch["depth"], batch["mask"])
        ce = task._identity_loss(out.latent, batch["subject_idx"])
        opt.zero_grad()
        ce.backward()
        opt.step()
    task.eval()
    with torch.no_grad():
        out = task(batch["depth"], batch["mask"])
    assert (out.latent.argmax(1) == batch["subject_idx"]).all()
    # a confident prediction is the subject's template: mask and depth inside it
    inside = batch["canon_mask"] > 0.5
    assert ((out.mask > 0.5) == inside).float().mean() > 0.99
    assert (out.depth - batch["canon_depth"])[inside].abs().max() < 0.02
    # an untrained net mixes the templates: its output is no template
    fresh = _task()
    fresh.net.set_templates(t_depth, t_mask)
    fresh.eval()
    with torch.no_grad():
        mixed = fresh(batch["depth"], batch["mask"])
    assert (mixed.depth - batch["canon_depth"])[inside].abs().max() > 0.05


def test_recall_settings_and_templates_are_checked():
    with pytest.raises(ValueError, match="n_subjects >= 2"):
        CanonicalTask(net={"image_size": SIZE, "recall_channels": [8]}, arch="recall", identity={"classes": 0})
    net = SubjectRecallNet(K, SIZE, (8,))
    with pytest.raises(ValueError, match=r"depth has shape \(3, 1, 32, 32\), expected \(4, 1, 32, 32\)"):
        net.set_templates(torch.zeros(3, 1, SIZE, SIZE), torch.zeros(3, 1, SIZE, SIZE))
    task = _task()
    batch, _, _ = _batch(classes=K + 1)
    with pytest.raises(ValueError, match="subject index 4 outside identity.classes=4"):
        task._identity_loss(task.net(batch["depth"], batch["mask"]).latent, batch["subject_idx"])


def test_fit_fills_the_templates_from_training_data_and_the_checkpoint_keeps_them(tmp_path):
    pl.seed_everything(0, workers=True)
    dm = CanonicalDataModule.from_flat(str(tmp_path / "data"), image_size=SIZE, n_subjects=3, n_poses=6, mesh_resolution=24,
                             n_folds=3, batch_size=8, kinds=["humanoid"], split="pose", seed=0)
    task = CanonicalTask(net={"image_size": SIZE, "recall_channels": [8, 16]}, arch="recall", mask_loss="bce",
                         identity={"classes": 3, "weight": 1.0}, phases={"use": False})
    tr = pl.Trainer(max_epochs=1, logger=False, enable_progress_bar=False, enable_model_summary=False,
                    accelerator="cpu", num_sanity_val_steps=0, default_root_dir=str(tmp_path))
    tr.fit(task, dm)
    depth, mask = dm.datasets["train"].canonical_templates(0)
    assert depth.shape == (3, 1, SIZE, SIZE) and mask.sum() > 0
    assert torch.equal(task.net.template_depth, depth) and torch.equal(task.net.template_mask, mask)
    # the canonical image of each subject is the target of its training items
    item = dm.datasets["train"][0]
    assert torch.equal(item["canon_depth"], depth[item["subject_idx"]])
    path = tmp_path / "recall.ckpt"
    tr.save_checkpoint(path)
    again = CanonicalTask.load_from_checkpoint(path, map_location="cpu", weights_only=True)
    assert torch.equal(again.net.template_depth, depth) and torch.equal(again.net.template_mask, mask)
