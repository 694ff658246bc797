"""Switches that make the completion step cheaper without changing the method (conf/task/completion.yaml):
``task.adversarial.gp_precision`` (the gradient penalty's critic pass in bf16) and ``task.compile_step`` (torch.compile of
the critic and generator objectives)."""
from __future__ import annotations

import logging

import lightning.pytorch as pl
import pytest
import torch
import yaml
from torch.nn.attention import SDPBackend, sdpa_kernel
from torch.utils.data import DataLoader

import lit3d.completion.compiled_step as compiled_step
from lit3d.completion.compiled_step import CompiledStep
from lit3d.completion.losses import gradient_penalty
from lit3d.completion.module import CompletionTask
from lit3d.utils.meta_autocast import MetaAutocast
from lit3d.utils.step_cost import CostCounter, SavedBytes
from tests.helpers.completion import grid_pair, tiny_nets, tiny_task
from tests.helpers.paths import REPO

pytestmark = pytest.mark.usefixtures("one_torch_thread")


def _task(nets: dict, **kw) -> CompletionTask:
    task = tiny_task(nets, **kw)
    with torch.no_grad():  # a non-zero attention weight, so the attention counts
        task.critic.attn.gamma.fill_(0.5)
    return task


def _batches(n: int) -> list[dict]:
    out = []
    for i in range(n):
        x, y = grid_pair(seed=i)
        out.append({"input": x, "target": y, "label": torch.tensor([0, 1]), "category": ["bench", "chair"]})
    return out


def _fit(task: CompletionTask, n: int = 1) -> None:
    trainer = pl.Trainer(accelerator="cpu", max_epochs=1, limit_val_batches=0, logger=False, enable_checkpointing=False,
                         enable_progress_bar=False, enable_model_summary=False)
    trainer.fit(task, train_dataloaders=DataLoader(_batches(n), batch_size=None))


def _weights(net: torch.nn.Module) -> list[torch.Tensor]:
    return [p.detach().clone() for p in net.parameters()]


def _penalty_and_grads(task: CompletionTask, precision: str, eps: torch.Tensor):
    x, y = grid_pair()
    fake = torch.rand(y.shape, generator=torch.Generator().manual_seed(1))
    task.critic.zero_grad(set_to_none=True)
    gp, norm = gradient_penalty(task.critic, x, y, fake, eps=eps, precision=precision)
    gp.backward()
    return gp.detach(), norm, {n: p.grad for n, p in task.critic.named_parameters()}


def test_switches_are_off_by_default_in_the_config():
    cfg = yaml.safe_load((REPO / "conf/task/completion.yaml").read_text())["task"]
    assert cfg["adversarial"]["gp_precision"] == "fp32" and cfg["compile_step"] is False


def test_fp32_penalty_is_the_penalty_of_before(completion_demo_nets):
    task = _task(completion_demo_nets)
    x, y = grid_pair()
    fake, eps = torch.rand_like(y), torch.tensor([0.3, 0.8])
    gp, norm = gradient_penalty(task.critic, x, y, fake, eps=eps)
    gp.backward()
    ours = [None if p.grad is None else p.grad.clone() for p in task.critic.parameters()]
    task.critic.zero_grad(set_to_none=True)
    # the penalty as it was written before the precision switch
    with torch.autocast("cpu", enabled=False):
        e = eps.view(2, 1, 1, 1, 1)
        yhat = (e * y + (1 - e) * fake).requires_grad_(True)
        with sdpa_kernel([SDPBackend.MATH]):
            d = task.critic(x.float(), yhat).float()
            (grad,) = torch.autograd.grad(d.sum(), yhat, create_graph=True)
        n = torch.sqrt(grad.flatten(1).pow(2).sum(1) + 1e-12)
        want = ((n - 1.0) ** 2).mean()
    want.backward()
    assert torch.equal(gp, want) and torch.equal(norm, n.mean())
    theirs = [p.grad for p in task.critic.parameters()]
    assert [a is None for a in ours] == [b is None for b in theirs]
    assert all(a is None or torch.equal(a, b) for a, b in zip(ours, theirs))


def test_bf16_penalty_is_close_to_fp32_and_its_gradients_reach_the_critic(completion_demo_nets):
    """Tolerance: bf16 keeps 8 significand bits (a rounding error up to 2^-9 = 0.2%); the critic's activations
    and weights are rounded at each of its 4 convolutions and its attention, in the forward, the input gradient
    and that gradient's backward, so errors of a few 0.1% add up. Measured on this critic's architecture over 12
    initialisations: the mean gradient norm within 1.1%, the critic's gradient within 5.7% (relative L2), cosine
    >= 0.998; the bounds below are 3% / 15% / 0.99 (margin for other CPUs' bf16 kernels). The penalty itself is
    near 1 here (gradient norms ~1e-3 at initialisation), so its bound is loose; the norm is the bf16 quantity."""
    task = _task(completion_demo_nets)
    eps = torch.tensor([0.3, 0.8])
    gp32, n32, g32 = _penalty_and_grads(task, "fp32", eps)
    gp16, n16, g16 = _penalty_and_grads(task, "bf16", eps)
    assert gp16.dtype == n16.dtype == torch.float32  # the norm and the penalty are fp32
    torch.testing.assert_close(n16, n32, rtol=3e-2, atol=0)
    torch.testing.assert_close(gp16, gp32, rtol=3e-2, atol=0)
    # the same parameters get gradients (the last conv's bias cannot: it shifts D, not its input gradient)
    assert {k for k, v in g16.items() if v is not None} == {k for k, v in g32.items() if v is not None}
    assert sum(v is not None for v in g16.values()) >= len(g16) - 1
    a = torch.cat([v.flatten() for v in g32.values() if v is not None])
    b = torch.cat([v.flatten() for v in g16.values() if v is not None])
    assert b.dtype == torch.float32 and torch.isfinite(b).all() and b.abs().sum() > 0
    assert float((a - b).norm() / a.norm()) < 0.15
    assert float(torch.nn.functional.cosine_similarity(a, b, 0)) > 0.99


def test_bf16_penalty_runs_the_critic_in_bf16(completion_demo_nets):
    task = _task(completion_demo_nets)
    seen = []
    hook = task.critic.layers[1].register_forward_hook(lambda m, i, o: seen.append(o.dtype))
    x, y = grid_pair()
    gradient_penalty(task.critic, x, y, y, precision="bf16")
    gradient_penalty(task.critic, x, y, y)
    hook.remove()
    assert seen == [torch.bfloat16, torch.float32]
    with pytest.raises(ValueError, match="precision"):
        gradient_penalty(task.critic, x, y, y, precision="fp16")
    with pytest.raises(ValueError, match="gp_precision"):
        CompletionTask(nets=tiny_nets(completion_demo_nets), adversarial={"gp_precision": "half"})


def test_meta_autocast_saves_for_backward_what_cpu_autocast_saves(completion_demo_nets):
    """The cost model's bf16 penalty (meta device, autocast emulated) keeps the bytes and FLOPs of the real one."""
    counts = {}
    for device in ("cpu", "meta"):
        with torch.device(device):
            task = CompletionTask(nets=tiny_nets(completion_demo_nets))
            x, y = torch.zeros(2, 1, 8, 8, 8), torch.zeros(2, 1, 32, 32, 32)
            eps = torch.full((2,), 0.5)
        for precision in ("fp32", "bf16"):
            with CostCounter() as c, SavedBytes() as s:
                gp, _ = gradient_penalty(task.critic, x, y, y, eps=eps, precision=precision)
                peak = s.peak
                gp.backward()
            counts[device, precision] = (c.flops, peak)
    assert counts["meta", "bf16"] == counts["cpu", "bf16"] and counts["meta", "fp32"] == counts["cpu", "fp32"]
    assert counts["cpu", "bf16"][0] == counts["cpu", "fp32"][0]  # the same FLOPs
    assert counts["cpu", "bf16"][1] < counts["cpu", "fp32"][1]  # fewer bytes saved for backward
    with torch.device("meta"), MetaAutocast(torch.bfloat16):
        assert torch.nn.functional.linear(torch.zeros(2, 3), torch.zeros(4, 3)).dtype == torch.bfloat16


def test_a_training_step_with_the_bf16_penalty_changes_the_weights(completion_demo_nets):
    task = _task(completion_demo_nets, gp_precision="bf16")
    critic, generator = _weights(task.critic), _weights(task.generator)
    _fit(task)
    assert task.critic_updates == 1 and task.generator_steps == 1
    assert any(not torch.equal(a, b) for a, b in zip(critic, task.critic.parameters()))
    assert any(not torch.equal(a, b) for a, b in zip(generator, task.generator.parameters()))
    assert all(torch.isfinite(p).all() for p in task.parameters())


def test_compile_step_runs_both_objectives_through_the_compiler(completion_demo_nets, monkeypatch):
    """The wiring, with a stand-in compiler (a real compile: the slow test below)."""
    compiled = []

    def fake_compile(fn):
        compiled.append(fn.__name__)
        return lambda *a: (calls.append(fn.__name__), fn(*a))[1]

    calls: list[str] = []
    monkeypatch.setattr(compiled_step.torch, "compile", fake_compile)
    task = _task(completion_demo_nets, compile_step=True)
    critic = _weights(task.critic)
    _fit(task, n=2)
    assert compiled == ["critic_objective", "generator_objective"]
    assert calls == ["critic_objective", "generator_objective"] * 2
    assert any(not torch.equal(a, b) for a, b in zip(critic, task.critic.parameters()))


def test_compile_step_falls_back_to_eager_with_a_warning(completion_demo_nets, monkeypatch, caplog):
    def broken(fn):
        def run(*a):
            raise RuntimeError("backend compiler failed")
        return run

    task = _task(completion_demo_nets, compile_step=True)
    x, y = grid_pair()
    torch.manual_seed(3)
    want, _ = task.critic_objective(x, y, True)
    step = CompiledStep(task, compile_fn=broken)
    with caplog.at_level(logging.WARNING, logger="lit3d.completion"):
        torch.manual_seed(3)
        got, _ = step("critic_objective", x, y, True)
    assert torch.equal(got, want) and "compiling critic_objective failed" in caplog.text
    assert step.fns["critic_objective"] == step.eager["critic_objective"]
    # no compiler at all: eager from the start, said once
    monkeypatch.setattr(compiled_step, "compile_unavailable", lambda device: "no C++ compiler")
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="lit3d.completion"):
        step = CompiledStep(task, compile_fn=broken)
    assert "unavailable (no C++ compiler)" in caplog.text and step.fns == step.eager


@pytest.mark.slow
def test_compiled_step_gives_the_eager_losses_and_gradients(completion_demo_nets):
    """A real torch.compile (inductor, CPU) of both objectives: the same losses and gradients as eager up to float
    rounding (inductor fuses and reorders reductions). Slow: compiling both objectives with their backward takes
    minutes on a shared CPU."""
    task = _task(completion_demo_nets, compile_step=True)
    step = CompiledStep(task)
    assert step.checked == set()  # compiled, not the fallback
    x, y = grid_pair()
    labels = torch.tensor([0, 1])
    for name, args, net in (("critic_objective", (x, y, True), task.critic),
                            ("generator_objective", (x, y, labels, True), task.generator)):
        out = []
        for fn in (getattr(task, name), lambda *a, n=name: step(n, *a)):
            task.zero_grad(set_to_none=True)
            torch.manual_seed(3)
            loss = fn(*args)[0]
            loss.backward()
            out.append((loss.detach(), [p.grad.clone() for p in net.parameters() if p.grad is not None]))
        (eager, g_eager), (comp, g_comp) = out
        assert step.fns[name] is not step.eager[name]  # it did compile
        torch.testing.assert_close(comp, eager, rtol=1e-4, atol=1e-6)
        assert len(g_comp) == len(g_eager)
        for a, b in zip(g_comp, g_eager):
            torch.testing.assert_close(a, b, rtol=1e-3, atol=1e-6)
