"""Options that cut the completion training step without changing the method (conf/task/completion.yaml):
``task.adversarial.gp_every`` (lazy gradient penalty) and ``task.adversarial.critic_concat`` (one critic pass over real +
fake)."""
from __future__ import annotations


import lightning.pytorch as pl
import pytest
import torch
import yaml
from torch.utils.data import DataLoader

from lit3d.completion.losses import critic_loss, gradient_penalty
from lit3d.completion.module import CompletionTask
from tests.helpers.completion import grid_pair, tiny_nets, tiny_task
from tests.helpers.paths import REPO

pytestmark = pytest.mark.usefixtures("one_torch_thread")


def _critic_grads(task: CompletionTask) -> list[torch.Tensor]:
    return [p.grad.clone() for p in task.critic.parameters()]


def test_options_are_off_by_default_in_the_config():
    cfg = yaml.safe_load((REPO / "conf/task/completion.yaml").read_text())["task"]
    assert cfg["adversarial"]["gp_every"] == 1 and cfg["adversarial"]["critic_concat"] is False


def test_gp_every_1_is_the_critic_loss_of_before(completion_demo_nets):
    task = tiny_task(completion_demo_nets)
    x, y = grid_pair()
    torch.manual_seed(5)
    loss, logs = task.critic_objective(x, y, with_penalty=True)
    loss.backward()
    ours = _critic_grads(task)
    task.critic.zero_grad(set_to_none=True)
    torch.manual_seed(5)  # the training step as it was: fakes, two critic passes, penalty, critic_loss
    with torch.no_grad():
        fake = torch.sigmoid(task.generator(x).logits)
    d_real, d_fake = task.critic(x, y), task.critic(x, fake)
    gp, _ = gradient_penalty(task.critic, x, y, fake)
    want = critic_loss(d_fake, d_real, gp, 10.0)
    want.backward()
    assert torch.equal(loss, want) and torch.equal(logs["gp"], gp)
    assert all(torch.equal(a, b) for a, b in zip(ours, _critic_grads(task)))


def test_gp_every_2_weighs_the_penalty_twice_and_skips_it_otherwise(completion_demo_nets):
    task = tiny_task(completion_demo_nets, gp_every=2)
    x, y = grid_pair()
    torch.manual_seed(5)
    with_gp, logs = task.critic_objective(x, y, with_penalty=True)
    without, logs_no = task.critic_objective(x, y, with_penalty=False)
    with torch.no_grad():
        fake = torch.sigmoid(task.generator(x).logits)
    d_real, d_fake = task.critic(x, y), task.critic(x, fake)
    torch.testing.assert_close(with_gp, d_fake.mean() - d_real.mean() + 2 * 10.0 * logs["gp"])
    torch.testing.assert_close(without, d_fake.mean() - d_real.mean())
    assert "gp" not in logs_no and logs["gp"] > 0


def test_gp_every_2_computes_the_penalty_on_alternate_critic_updates(completion_demo_nets):
    task = tiny_task(completion_demo_nets, gp_every=2, critic_steps=1)
    calls = []
    penalty = task.critic_penalty

    def spy(*a):
        calls.append(task.critic_updates)
        return penalty(*a)

    task.critic_penalty = spy
    batches = []
    for i in range(4):
        x, y = grid_pair(seed=i)
        batches.append({"input": x, "target": y, "label": torch.tensor([0, 1]), "category": ["bench", "chair"]})
    trainer = pl.Trainer(accelerator="cpu", max_epochs=1, limit_val_batches=0, logger=False, enable_checkpointing=False,
                         enable_progress_bar=False, enable_model_summary=False)
    trainer.fit(task, train_dataloaders=DataLoader(batches, batch_size=None))
    assert task.critic_updates == 4 and calls == [0, 2]


def test_gp_every_below_1_is_refused(completion_demo_nets):
    with pytest.raises(ValueError, match="gp_every"):
        CompletionTask(nets=tiny_nets(completion_demo_nets), adversarial={"gp_every": 0})


def test_critic_concat_gives_the_two_passes_scores_and_gradients(completion_demo_nets):
    two, one = tiny_task(completion_demo_nets), tiny_task(completion_demo_nets, critic_concat=True)
    one.critic.load_state_dict(two.critic.state_dict())
    with torch.no_grad():  # a non-zero attention weight, so the attention counts
        for t in (one, two):
            t.critic.attn.gamma.fill_(0.5)
    x, y = grid_pair()
    fake = torch.rand_like(y)
    grads = []
    for task in (two, one):
        d_real, d_fake = task.critic_scores(x, y, fake)
        (d_fake.mean() - d_real.mean()).backward()
        grads.append((d_real.detach(), d_fake.detach(), _critic_grads(task)))
    (r2, f2, g2), (r1, f1, g1) = grads
    torch.testing.assert_close(r1, r2, rtol=1e-5, atol=1e-6)
    torch.testing.assert_close(f1, f2, rtol=1e-5, atol=1e-6)
    assert not torch.equal(r1, f1)  # real and fake scores are not swapped or shared
    for a, b in zip(g1, g2):
        torch.testing.assert_close(a, b, rtol=1e-4, atol=1e-6)
