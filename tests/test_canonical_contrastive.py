"""The contrastive identity term (task.contrastive.weight) and the batches it needs (data.training.batch_poses):
the loss against a loop written from the paper's formula, its wiring into the training step and the
encoder or the output, learning, refused settings; the grouped batches' contents and order."""
import math

import pytest
import torch

from datamodules.canonical.batches import SubjectGroupedBatches
from datamodules.cache import DataError
from lit3d.canonical.contrastive import ContrastiveEmbedder, supervised_contrastive
from lit3d.canonical.module import CanonicalTask
from tests.helpers.canonical import subject_batch, tiny_canonical_net, step_losses


def _reference(z: torch.Tensor, labels: list[int], t: float) -> float:
    """Khosla et al. (2020) eq. 2, L_out, one anchor at a time in plain Python."""
    z = [[x / math.sqrt(sum(y * y for y in v)) for x in v] for v in z.tolist()]
    dot = [[sum(a * b for a, b in zip(u, v)) / t for v in z] for u in z]
    per_anchor = []
    for i in range(len(z)):
        pos = [p for p in range(len(z)) if p != i and labels[p] == labels[i]]
        if not pos:
            continue
        denom = sum(math.exp(dot[i][a]) for a in range(len(z)) if a != i)
        per_anchor.append(-sum(math.log(math.exp(dot[i][p]) / denom) for p in pos) / len(pos))
    return sum(per_anchor) / len(per_anchor)


def test_loss_matches_the_formula_and_orders_embeddings():
    g = torch.Generator().manual_seed(0)
    z = torch.randn(10, 5, generator=g)
    labels = [0, 0, 1, 1, 1, 2, 3, 3, 4, 0]  # subjects 2 and 4 alone: no anchors
    got = supervised_contrastive(z, torch.tensor(labels), 0.5)
    assert got.item() == pytest.approx(_reference(z, labels, 0.5), rel=1e-5)
    # clustered by subject is cheaper than the same points with the labels shuffled
    centres = torch.eye(4) * 5
    lab = torch.tensor([0, 0, 1, 1, 2, 2, 3, 3])
    clustered = centres[lab] + 0.1 * torch.randn(8, 4, generator=g)
    assert supervised_contrastive(clustered, lab, 0.1) < supervised_contrastive(clustered, lab[[0, 2, 4, 6, 1, 3, 5, 7]], 0.1)


def test_loss_without_positives_is_zero_and_differentiable():
    z = torch.randn(4, 3, requires_grad=True)
    loss = supervised_contrastive(z, torch.arange(4), 0.1)
    loss.backward()
    assert loss.item() == 0.0 and z.grad is not None
    with pytest.raises(ValueError, match="temperature must be > 0"):
        supervised_contrastive(z, torch.arange(4), 0.0)


@pytest.mark.parametrize("on", ["latent", "output"])
def test_training_step_adds_the_weighted_term_and_it_reaches_the_net(compose_cfg, on):
    batch = subject_batch()
    node = {"weight": "{w}", "embed": on, "dim": 16, "channels": [8, 16]}
    losses, task = step_losses(compose_cfg, batch, (0.0, 2.0), contrastive=node)
    out = task.net(batch["depth"], batch["mask"])
    emb = task.contrastive_head(out)
    assert emb.shape == (8, 16)
    term = supervised_contrastive(emb, batch["subject_idx"], 0.1)
    assert losses[2.0].item() == pytest.approx(losses[0.0].item() + 2.0 * term.item(), rel=1e-4)
    term.backward()
    reached = task.net.msfe.encoders[0] if on == "latent" else task.net
    assert any(p.grad is not None and p.grad.abs().sum() > 0 for p in reached.parameters())


def test_the_latent_term_learns_to_tell_the_subjects_apart(compose_cfg):
    torch.manual_seed(0)
    task = CanonicalTask(net=tiny_canonical_net(compose_cfg), mask_loss="bce", phases={"use": False},
                         contrastive={"weight": 1.0, "dim": 16})
    batch = subject_batch(n=8, classes=4)
    opt = torch.optim.Adam(task.parameters(), 3e-3)
    losses = []
    for _ in range(40):
        loss = supervised_contrastive(task.contrastive_head(task.net(batch["depth"], batch["mask"])),
                                      batch["subject_idx"], 0.1)
        opt.zero_grad()
        loss.backward()
        opt.step()
        losses.append(loss.item())
    assert losses[-1] < 0.3 * losses[0], (losses[0], losses[-1])
    z = torch.nn.functional.normalize(task.contrastive_head(task.net(batch["depth"], batch["mask"])), dim=1)
    sim = (z @ z.t()).fill_diagonal_(-2)
    assert (batch["subject_idx"][sim.argmax(1)] == batch["subject_idx"]).all()  # nearest = own subject


def test_contrastive_settings_are_checked(compose_cfg):
    with pytest.raises(ValueError, match="task.contrastive.embed must be one of"):
        CanonicalTask(net=tiny_canonical_net(compose_cfg), contrastive={"weight": 1.0, "embed": "pixels", "dim": 8})
    with pytest.raises(ValueError, match="embed_dim >= 1"):
        CanonicalTask(net=tiny_canonical_net(compose_cfg), contrastive={"weight": 1.0, "dim": 0})
    assert CanonicalTask(net=tiny_canonical_net(compose_cfg)).contrastive_head is None  # off by default
    with pytest.raises(ValueError, match="needs the MSFE latent"):
        ContrastiveEmbedder("latent", 8, 4, [4])(type("Out", (), {"latent": None})())


def _records(counts: dict[str, int]) -> list[dict]:
    return [{"subject": s, "pose": p} for s, n in counts.items() for p in range(n)]


def test_grouped_batches_hold_whole_groups_of_one_subject_once_each():
    records = _records({"a": 6, "b": 5, "c": 4, "d": 2, "e": 1})
    sampler = SubjectGroupedBatches(records, batch_size=4, poses=2, seed=0)
    epoch = list(sampler)
    assert len(epoch) == len(sampler) == 4  # 3 + 2 + 2 + 1 groups of 2 = 8 groups, 2 a batch
    flat = [i for b in epoch for i in b]
    assert len(flat) == len(set(flat)) == 16  # no item twice; b and e lose their odd item this epoch
    for b in epoch:
        subjects = [records[i]["subject"] for i in b]
        assert subjects[0] == subjects[1] and subjects[2] == subjects[3]
    again = SubjectGroupedBatches(records, batch_size=4, poses=2, seed=0)
    assert list(again) == epoch and list(again) != epoch  # the same seed repeats; the next epoch reshuffles
    again.set_epoch(0)
    assert list(again) == epoch


def test_grouped_batches_refuse_sizes_they_cannot_fill():
    records = _records({"a": 3, "b": 3})
    with pytest.raises(DataError, match="batch_size \\(6\\) a multiple"):
        SubjectGroupedBatches(records, batch_size=6, poses=4, seed=0)
    with pytest.raises(DataError, match="batch_poses=1"):
        SubjectGroupedBatches(records, batch_size=4, poses=1, seed=0)
    with pytest.raises(DataError, match="no training subject has that many items \\(most: 3\\)"):
        SubjectGroupedBatches(records, batch_size=8, poses=4, seed=0)
