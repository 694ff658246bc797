"""The subject classifier (task.identity.weight) on the MSFE latent: wired into the loss and the encoder,
learns its targets, refuses settings it cannot serve."""
import pytest
import torch

from lit3d.canonical.module import CanonicalTask
from tests.helpers.canonical import step_losses, subject_batch, tiny_canonical_net






def test_identity_loss_reaches_the_encoder_and_learns_the_subjects(compose_cfg):
    torch.manual_seed(0)
    task = CanonicalTask(net=tiny_canonical_net(compose_cfg), mask_loss="bce", phases={"use": False},
                         identity={"weight": 1.0, "classes": 4})
    batch = subject_batch()
    latent = task.net(batch["depth"], batch["mask"]).latent
    assert latent.shape == (8, task.identity_head.in_features)
    loss = task._identity_loss(latent, batch["subject_idx"])
    loss.backward()
    enc = task.net.msfe.encoders[0]
    assert any(p.grad is not None and p.grad.abs().sum() > 0 for p in enc.parameters())  # not detached
    opt = torch.optim.Adam(task.parameters(), 3e-3)
    first = None
    for _ in range(60):
        out = task.net(batch["depth"], batch["mask"])
        ce = task._identity_loss(out.latent, batch["subject_idx"])
        first = first if first is not None else ce.item()
        opt.zero_grad()
        ce.backward()
        opt.step()
    logits = task.identity_head(task.net(batch["depth"], batch["mask"]).latent)
    assert (logits.argmax(1) == batch["subject_idx"]).float().mean() == 1.0
    assert ce.item() < 0.2 * first, (first, ce.item())


def test_identity_settings_are_checked(compose_cfg):
    with pytest.raises(ValueError, match="task.identity.classes >= 2"):
        CanonicalTask(net=tiny_canonical_net(compose_cfg), identity={"weight": 1.0, "classes": 0})
    with pytest.raises(ValueError, match="arch=unet"):
        CanonicalTask(net=tiny_canonical_net(compose_cfg), arch="unet", identity={"weight": 1.0, "classes": 4})
    task = CanonicalTask(net=tiny_canonical_net(compose_cfg), identity={"weight": 1.0, "classes": 2})
    batch = subject_batch(classes=4)
    with pytest.raises(ValueError, match="subject index 3 outside identity.classes=2"):
        task._identity_loss(task.net(batch["depth"], batch["mask"]).latent, batch["subject_idx"])
    assert CanonicalTask(net=tiny_canonical_net(compose_cfg)).identity_head is None  # off by default




def test_training_step_adds_the_weighted_identity_term(compose_cfg):
    batch = subject_batch()
    losses, task = step_losses(compose_cfg, batch, (0.0, 2.0), identity={"weight": "{w}", "classes": 4})
    ce = task._identity_loss(task.net(batch["depth"], batch["mask"]).latent, batch["subject_idx"])
    assert losses[2.0].item() == pytest.approx(losses[0.0].item() + 2.0 * ce.item(), rel=1e-4)
