"""CompletionTask behaviour that needs no generated dataset: NaN handling, warm-up, meta summary."""
from __future__ import annotations

import lightning.pytorch as pl
import pytest
import torch
from torch.utils.data import DataLoader

from lit3d.nets.completion import DEMO
from lit3d.tasks.completion import CompletionTask, NonFiniteLossError


def _batches(n: int = 4, nan: bool = False) -> list[dict]:
    g = torch.Generator().manual_seed(0)
    out = []
    for _ in range(n):
        target = (torch.rand(2, 1, 64, 64, 64, generator=g) < 0.1).float()
        if nan:
            target[0, 0, 0, 0, 0] = float("nan")
        inp = torch.nn.functional.max_pool3d(target, 4)
        out.append({"input": inp, "target": target, "label": torch.tensor([0, 1]), "category": ["bench", "chair"]})
    return out


def _fit(task: CompletionTask, batches: list[dict], steps: int) -> pl.Trainer:
    trainer = pl.Trainer(accelerator="cpu", max_epochs=1, limit_train_batches=steps, limit_val_batches=0,
                         logger=False, enable_checkpointing=False, enable_progress_bar=False,
                         enable_model_summary=False)
    trainer.fit(task, train_dataloaders=DataLoader(batches, batch_size=None))
    return trainer


def test_nonfinite_loss_stops_with_step_and_term():
    task = CompletionTask(nets={"preset": "demo"})
    with pytest.raises(NonFiniteLossError, match=r"generator step 0 .*critic|generator step 0 .*bce"):
        _fit(task, _batches(nan=True), steps=1)


def test_nonfinite_loss_can_skip_steps():
    task = CompletionTask(nets={"preset": "demo"}, on_nonfinite="skip")
    before = {k: v.clone() for k, v in task.generator.state_dict().items()}
    _fit(task, _batches(n=2, nan=True), steps=2)
    assert task.skipped_steps >= 2
    after = task.generator.state_dict()
    assert all(torch.equal(before[k], after[k]) for k in before), "a skipped step must not update the generator"


def test_adversarial_warmup_skips_critic_updates():
    task = CompletionTask(nets={"preset": "demo"}, adversarial_start_epoch=1)
    _fit(task, _batches(n=2), steps=2)
    opt_g, opt_d = task.optimizers()
    assert not opt_d.optimizer.state, "critic must not step during warm-up"
    assert {int(s["step"]) for s in opt_g.optimizer.state.values()} == {2}


def test_summary_rows_on_meta_device_paper_scale():
    with torch.device("meta"):
        rows = CompletionTask.summary_rows({"nets": {"preset": "paper"}})
    gen = next(r for r in rows if r["component"] == "generator")
    assert tuple(gen["input"]) == (1, 1, 64, 64, 64) and tuple(gen["output"]) == (1, 1, 256, 256, 256)
    assert gen["params"] > 100_000_000
    assert DEMO["out_res"] == 64


def test_stage_bce_is_weighted_bce_of_the_pooled_target():
    from lit3d.losses import weighted_bce_with_logits

    task = CompletionTask(nets={"preset": "demo"}, stage_weight=0.5)
    g = torch.Generator().manual_seed(1)
    target = (torch.rand(2, 1, 64, 64, 64, generator=g) < 0.1).float()
    logits = [torch.randn(2, 1, 16, 16, 16, generator=g) for _ in range(2)]
    # hand-pooled: a coarse voxel is occupied when any of its 4^3 cell is
    small = (target.reshape(2, 1, 16, 4, 16, 4, 16, 4).amax(dim=(3, 5, 7)))
    want = (weighted_bce_with_logits(logits[0], small, 0.35) + weighted_bce_with_logits(logits[1], small, 0.35)) / 2
    assert torch.allclose(task._stage_bce(logits, target), want)
