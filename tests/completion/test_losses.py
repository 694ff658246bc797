"""Completion losses against hand computations."""
from __future__ import annotations

import math

import pytest
import torch
import torch.nn as nn
import torch.nn.functional as F

from lit3d.completion.losses import critic_loss, generator_adv_loss, gradient_penalty, weighted_bce_with_logits
from lit3d.completion.nets import Critic


pytestmark = pytest.mark.usefixtures("one_torch_thread")


def test_weighted_bce_matches_hand_computation():
    logits = torch.tensor([[0.0, 2.0], [-1.0, 3.0]])
    target = torch.tensor([[1.0, 0.0], [0.0, 1.0]])
    alpha = 0.35

    def sig(z):
        return 1.0 / (1.0 + math.exp(-z))

    terms = [
        math.log(sig(0.0)),                  # y = 1
        alpha * math.log(1 - sig(2.0)),      # y = 0
        alpha * math.log(1 - sig(-1.0)),     # y = 0
        math.log(sig(3.0)),                  # y = 1
    ]
    expected = -sum(terms) / 4
    assert weighted_bce_with_logits(logits, target, alpha).item() == pytest.approx(expected, rel=1e-6)


def test_weighted_bce_alpha_one_is_torch_bce_and_stable():
    torch.manual_seed(0)
    logits = torch.randn(2, 1, 4, 4, 4) * 5
    target = (torch.rand_like(logits) < 0.3).float()
    torch.testing.assert_close(weighted_bce_with_logits(logits, target, 1.0),
                               F.binary_cross_entropy_with_logits(logits, target))
    # extreme logits: finite, fp32 even from bf16 inputs
    big = torch.tensor([100.0, -100.0]).to(torch.bfloat16)
    out = weighted_bce_with_logits(big, torch.tensor([0.0, 1.0]))
    assert out.dtype == torch.float32 and torch.isfinite(out)
    assert out.item() == pytest.approx((0.35 * 100 + 100) / 2, rel=1e-3)


class LinearCritic(nn.Module):
    """D(partial, y) = sum(w * y) + sum(partial): gradient wrt y is w."""

    def __init__(self, w: torch.Tensor):
        super().__init__()
        self.w = nn.Parameter(w)

    def forward(self, partial, y):
        return (self.w * y).flatten(1).sum(1) + partial.flatten(1).sum(1)


def test_gradient_penalty_linear_critic_is_exact():
    torch.manual_seed(0)
    w = torch.randn(1, 1, 3, 3, 3)
    critic = LinearCritic(w.clone())
    partial = torch.rand(2, 1, 2, 2, 2)
    real, fake = torch.rand(2, 1, 3, 3, 3), torch.rand(2, 1, 3, 3, 3)
    gp, norm = gradient_penalty(critic, partial, real, fake)
    wn = w.norm().item()
    assert gp.item() == pytest.approx((wn - 1) ** 2, rel=1e-5)
    assert norm.item() == pytest.approx(wn, rel=1e-5)
    # the penalty's gradient wrt w: d/dw (||w|| - 1)^2 = 2 (||w|| - 1) w / ||w||
    gp.backward()
    torch.testing.assert_close(critic.w.grad, 2 * (wn - 1) * w / wn, rtol=1e-4, atol=1e-6)


def test_gradient_penalty_uses_interpolates_and_fp32():
    # D(y) = sum(y^2): grad = 2 yhat, yhat = eps real + (1 - eps) fake
    class Quad(nn.Module):
        def forward(self, partial, y):
            assert y.dtype == torch.float32 and not torch.is_autocast_enabled()
            return (y**2).flatten(1).sum(1)

    real = torch.ones(2, 1, 2, 2, 2)
    fake = torch.zeros(2, 1, 2, 2, 2)
    eps = torch.tensor([0.25, 0.5])
    with torch.autocast("cpu", dtype=torch.bfloat16):
        gp, norm = gradient_penalty(Quad(), torch.zeros(2, 1, 1, 1, 1), real.bfloat16(), fake.bfloat16(), eps=eps)
    # ||2 eps * 1||_2 over 8 voxels = 2 eps sqrt(8)
    norms = 2 * eps * math.sqrt(8)
    assert gp.dtype == torch.float32
    assert gp.item() == pytest.approx(((norms - 1) ** 2).mean().item(), rel=1e-5)
    assert norm.item() == pytest.approx(norms.mean().item(), rel=1e-5)


def test_gradient_penalty_through_attention_critic_backprops():
    torch.manual_seed(0)
    critic = Critic(16, (4, 4, 4), attention_res=4, sigmoid=False)
    with torch.no_grad():
        critic.attn.gamma.fill_(0.5)
    partial = (torch.rand(2, 1, 4, 4, 4) < 0.3).float()
    real, fake = torch.rand(2, 1, 16, 16, 16), torch.rand(2, 1, 16, 16, 16)
    gp, _ = gradient_penalty(critic, partial, real, fake)
    gp.backward()  # double backward through conv, LeakyReLU and attention
    assert critic.attn.f.weight.grad.abs().sum() > 0
    assert critic.layers[0][0].weight.grad.abs().sum() > 0


def test_wgan_losses():
    d_fake = torch.tensor([1.0, 3.0])
    d_real = torch.tensor([2.0, 6.0])
    gp = torch.tensor(0.5)
    assert critic_loss(d_fake, d_real, gp).item() == pytest.approx(2.0 - 4.0 + 10 * 0.5)
    assert critic_loss(d_fake, d_real, gp, lam=1.0).item() == pytest.approx(2.0 - 4.0 + 0.5)
    assert generator_adv_loss(d_fake).item() == pytest.approx(-2.0)
