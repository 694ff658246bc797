"""Training-health callback (lit3d/callbacks/health.py) and the completion task's parameter groups."""
from __future__ import annotations

import csv

import lightning.pytorch as pl
import pytest
import torch
from lightning.pytorch.loggers import CSVLogger
from torch.utils.data import DataLoader, TensorDataset

from lit3d.callbacks.health import TrainingHealth, group_stats, parameter_groups
from lit3d.completion.module import CompletionTask


class _TwoLayers(pl.LightningModule):
    """Manual optimisation, like the GAN: one Adam step per batch; ``frozen`` never updates."""

    def __init__(self):
        super().__init__()
        self.automatic_optimization = False
        self.first, self.second, self.frozen = torch.nn.Linear(3, 4), torch.nn.Linear(4, 1), torch.nn.Linear(1, 1)
        self.frozen.requires_grad_(False)
        self.history: list[dict[str, list[torch.Tensor]]] = []

    def health_groups(self):
        return {"first layer": list(self.first.parameters()), "second": list(self.second.parameters()),
                "frozen": list(self.frozen.parameters())}

    def training_step(self, batch, batch_idx):
        opt = self.optimizers()
        self.history.append({k: [p.detach().clone() for p in ps] for k, ps in self.health_groups().items()})
        loss = (self.second(torch.relu(self.first(batch[0]))) - batch[1]).pow(2).mean()
        opt.zero_grad()
        self.manual_backward(loss)
        opt.step()

    def configure_optimizers(self):
        return torch.optim.Adam([p for p in self.parameters() if p.requires_grad], lr=0.01)


def test_health_logs_update_ratios_every_n_batches(tmp_path):
    torch.manual_seed(0)
    data = DataLoader(TensorDataset(torch.randn(20, 3), torch.randn(20, 1)), batch_size=4)
    model = _TwoLayers()
    cb = TrainingHealth(every_n_batches=2)
    trainer = pl.Trainer(max_epochs=1, logger=CSVLogger(tmp_path), callbacks=[cb], enable_checkpointing=False,
                         enable_progress_bar=False, enable_model_summary=False)
    trainer.fit(model, data)
    rows = list(csv.DictReader(open(next(tmp_path.rglob("metrics.csv")))))
    logged = [r for r in rows if r.get("health/first_layer/update_ratio")]
    assert [int(r["step"]) for r in logged] == [1, 3, 5]  # batches 0, 2, 4; logged after their step
    # independent reference: the weights before batch 4 and after training
    before, after = model.history[4]["first layer"], list(model.first.parameters())
    ref = float(torch.sqrt(sum((a.detach() - b).pow(2).sum() for a, b in zip(after, before)))
                / torch.sqrt(sum(b.pow(2).sum() for b in before)))
    assert float(logged[-1]["health/first_layer/update_ratio"]) == pytest.approx(ref, rel=1e-5)
    assert 1e-4 < ref < 1.0
    assert float(logged[-1]["health/first_layer/grad_norm"]) > 0
    assert "health/frozen/update_ratio" not in rows[0]  # no trainable parameter: no group
    assert cb.state_dict() == {"batches": 5}


def test_group_stats_counts_missing_grads_as_zero():
    p, q = torch.nn.Parameter(torch.ones(4)), torch.nn.Parameter(torch.ones(12))
    p.grad = torch.full((4,), 2.0)
    s = group_stats([p, q], [torch.zeros(4), torch.ones(12) * 0.5])
    assert s["grad_norm"] == pytest.approx(4.0) and s["grad_rms"] == pytest.approx(1.0)
    assert s["update_ratio"] == pytest.approx((4 + 12 * 0.25) ** 0.5 / (12 * 0.25) ** 0.5)


def test_completion_groups_cover_every_parameter_once(completion_demo_nets):
    task = CompletionTask(nets=dict(completion_demo_nets))
    groups = parameter_groups(task)
    assert {"stage_1_encoder", "stage_1_latent_fc", "stage_1_selector", "stage_3_decoder", "critic",
            "classifier"} <= set(groups)
    ids = [id(p) for ps in groups.values() for p in ps]
    assert len(ids) == len(set(ids))
    assert set(ids) == {id(p) for p in task.parameters() if p.requires_grad}
