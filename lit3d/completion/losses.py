"""Losses. Shape completion (thesis ch. 3): weighted BCE and WGAN-GP terms.

All completion losses compute in fp32 (autocast off, inputs cast up), so they are safe under
``bf16-mixed`` / ``16-mixed`` training; with ``precision="bf16"`` the gradient penalty runs its critic pass
(only) under bf16 autocast, its norm and mean staying fp32.
"""
from __future__ import annotations

import contextlib
from collections.abc import Callable

import torch
import torch.nn.functional as F

from lit3d.utils.meta_autocast import MetaAutocast

# task.adversarial.gp_precision: the dtype of the gradient penalty's critic pass (gradient_penalty)
PENALTY_PRECISIONS = ("fp32", "bf16")


def _autocast_off(t: torch.Tensor):
    if t.device.type == "meta":  # the cost model's device (lit3d.completion.step_cost): no autocast there
        return contextlib.nullcontext()
    return torch.autocast(device_type=t.device.type, enabled=False)


def _penalty_autocast(t: torch.Tensor, precision: str):
    """The penalty's critic pass: as it is (fp32: autocast already off) or under bf16 autocast (emulated on meta)."""
    if precision == "fp32":
        return contextlib.nullcontext()
    if t.device.type == "meta":
        return MetaAutocast(torch.bfloat16)
    return torch.autocast(device_type=t.device.type, dtype=torch.bfloat16)


def weighted_bce_with_logits(logits: torch.Tensor, target: torch.Tensor, alpha: float = 0.35) -> torch.Tensor:
    """Modified BCE of thesis eq. 3.5 with empty voxels down-weighted by ``alpha``.

    ``L = -mean[ y log p + alpha (1 - y) log(1 - p) ]``, ``p = sigmoid(logits)``, computed stably
    from logits in fp32 (``log p = logsigmoid(z)``, ``log(1 - p) = logsigmoid(-z)``).

    Args:
        logits: any shape, e.g. ``(B, 1, R, R, R)``, any float dtype.
        target: same shape, values in [0, 1] (``y``).
        alpha: weight of the empty-voxel term (``alpha = 1`` is the plain BCE).
    Returns: scalar fp32 tensor.
    """
    with _autocast_off(logits):
        z = logits.float()
        y = target.float()
        return -(y * F.logsigmoid(z) + alpha * (1.0 - y) * F.logsigmoid(-z)).mean()


def resolve_loss_scale(loss_scale: float | str, out_res: int) -> float:
    """``task.optimizer.loss_scale`` as a number: ``"voxels"`` -> ``out_res**3`` (the weighted BCE summed over
    a shape's voxels, averaged over the batch), a number -> itself (1 = the per-voxel mean).

    Raises:
        ValueError: for another string or a non-positive number.
    """
    if isinstance(loss_scale, str):
        if loss_scale != "voxels":
            raise ValueError(f"task.optimizer.loss_scale={loss_scale!r}: use 'voxels' or a positive number")
        return float(out_res) ** 3
    if not float(loss_scale) > 0:
        raise ValueError(f"task.optimizer.loss_scale={loss_scale!r} must be positive")
    return float(loss_scale)


def gradient_penalty(
    critic: Callable[[torch.Tensor, torch.Tensor], torch.Tensor],
    partial: torch.Tensor,
    real: torch.Tensor,
    fake: torch.Tensor,
    eps: torch.Tensor | None = None,
    precision: str = "fp32",
) -> tuple[torch.Tensor, torch.Tensor]:
    """WGAN-GP penalty ``E[(||grad_yhat D(yhat | x)||_2 - 1)^2]`` on random interpolates.

    ``yhat = eps * real + (1 - eps) * fake`` with ``eps ~ U(0, 1)`` per sample (fp32); ``real`` and ``fake``
    are detached. The critic runs with the MATH attention backend whatever the precision: the fused CUDA
    attention kernels (flash, memory-efficient, cuDNN) have no double backward; MATH is made of matmuls and a
    softmax, which have (in bf16 it reduces in fp32 unless
    ``torch.backends.cuda.allow_fp16_bf16_reduction_math_sdp(True)``).

    ``precision``:
        ``"fp32"``: autocast off, everything in fp32 (the thesis's step).
        ``"bf16"``: the critic's forward under bf16 autocast (its convolutions and attention in bf16; their
        double backward runs in the dtypes autocast chose, as ``torch.autocast`` documents for backward).
        The input gradient is taken with autocast off, as PyTorch's AMP example of a gradient penalty does
        (``docs/notes/amp_examples``, "Gradient penalty"), and arrives in fp32 (the backward of autocast's cast
        of ``yhat``); its norm, the penalty and its mean are fp32; the critic's parameters stay fp32 and their
        gradients accumulate in fp32. No loss scaling: bf16 has fp32's exponent range. On the meta device
        (the cost model) autocast is emulated by :class:`lit3d.utils.meta_autocast.MetaAutocast`.

    Args:
        critic: ``critic(partial, shape) -> (B,)``.
        partial: ``(B, 1, r, r, r)`` conditioning input.
        real, fake: ``(B, 1, R, R, R)`` shapes (probabilities).
        eps: optional ``(B,)`` interpolation weights (drawn uniformly when None).
        precision: one of :data:`PENALTY_PRECISIONS`.
    Returns:
        (penalty scalar fp32 with graph for backward, mean gradient norm scalar detached).
    """
    from torch.nn.attention import SDPBackend, sdpa_kernel

    if precision not in PENALTY_PRECISIONS:
        raise ValueError(f"gradient penalty precision {precision!r}: one of {PENALTY_PRECISIONS}")
    b = real.shape[0]
    with _autocast_off(real):
        if eps is None:
            eps = torch.rand(b, device=real.device)
        e = eps.float().view(b, *([1] * (real.dim() - 1)))
        yhat = (e * real.detach().float() + (1.0 - e) * fake.detach().float()).requires_grad_(True)
        with sdpa_kernel([SDPBackend.MATH]):
            with _penalty_autocast(real, precision):
                d = critic(partial.float(), yhat)
            (grad,) = torch.autograd.grad(d.float().sum(), yhat, create_graph=True)
        norm = torch.sqrt(grad.float().flatten(1).pow(2).sum(1) + 1e-12)
        return ((norm - 1.0) ** 2).mean(), norm.mean().detach()


def critic_loss(d_fake: torch.Tensor, d_real: torch.Tensor, gp: torch.Tensor, lam: float = 10.0) -> torch.Tensor:
    """WGAN-GP critic loss ``E[D(fake)] - E[D(real)] + lam * gp``; ``d_*`` are ``(B,)``; scalar fp32."""
    return d_fake.float().mean() - d_real.float().mean() + lam * gp.float()


def generator_adv_loss(d_fake: torch.Tensor) -> torch.Tensor:
    """WGAN generator loss ``-E[D(G(x) | x)]``; ``d_fake`` is ``(B,)``; scalar fp32."""
    return -d_fake.float().mean()
