"""The subject classifier (task.identity.weight) and the phenotype regression (task.phenotype.weight)
on the MSFE latent: wired into the loss and the encoder, learn their targets, refuse settings they
cannot serve."""
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


def _pheno_batch(n=8, size=32):
    """Subjects told apart by size; two phenotypes that follow the size (what a body-shape code must say)."""
    batch = subject_batch(n, size)
    k = batch["subject_idx"].float()
    batch["phenotype"] = torch.stack([k / 3, 1 - k / 3], 1)
    return batch


def test_phenotype_regression_reaches_the_encoder_and_learns_the_shapes(compose_cfg):
    torch.manual_seed(0)
    task = CanonicalTask(net=tiny_canonical_net(compose_cfg), mask_loss="bce", phases={"use": False},
                         phenotype={"weight": 1.0, "dims": 2})
    batch = _pheno_batch()
    err = task._phenotype_error(task.net(batch["depth"], batch["mask"]).latent, batch)
    assert err.shape == (8, 2)
    err.pow(2).mean().backward()
    assert any(p.grad is not None and p.grad.abs().sum() > 0 for p in task.net.msfe.encoders[0].parameters())
    opt = torch.optim.Adam(task.parameters(), 3e-3)
    first = None
    for _ in range(60):
        mse = task._phenotype_error(task.net(batch["depth"], batch["mask"]).latent, batch).pow(2).mean()
        first = first if first is not None else mse.item()
        opt.zero_grad()
        mse.backward()
        opt.step()
    assert mse.item() < 0.05 * first, (first, mse.item())


def test_training_step_adds_the_weighted_phenotype_term_and_needs_targets(compose_cfg):
    batch = _pheno_batch()
    losses, task = step_losses(compose_cfg, batch, (0.0, 3.0), phenotype={"weight": "{w}", "dims": 2})
    mse = task._phenotype_error(task.net(batch["depth"], batch["mask"]).latent, batch).pow(2).mean()
    assert losses[3.0].item() == pytest.approx(losses[0.0].item() + 3.0 * mse.item(), rel=1e-4)
    with pytest.raises(ValueError, match="data.phenotype_targets=true"):
        task.training_step(subject_batch(), 0)
    with pytest.raises(ValueError, match="task.phenotype.dims=3"):
        bad = CanonicalTask(net=tiny_canonical_net(compose_cfg), phenotype={"weight": 1.0, "dims": 3})
        bad._phenotype_error(bad.net(batch["depth"], batch["mask"]).latent, batch)
    with pytest.raises(ValueError, match="task.phenotype.dims >= 1"):
        CanonicalTask(net=tiny_canonical_net(compose_cfg), phenotype={"weight": 1.0, "dims": 0})
    assert CanonicalTask(net=tiny_canonical_net(compose_cfg)).phenotype_head is None  # off by default
