"""CompletionTask behaviour that needs no generated dataset: NaN handling, warm-up, meta summary."""
from __future__ import annotations

import lightning.pytorch as pl
import pytest
import torch
from torch.utils.data import DataLoader

from lit3d.completion.module import CompletionTask, NonFiniteLossError


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


def test_nonfinite_loss_stops_with_step_and_term(completion_demo_nets):
    task = CompletionTask(nets=completion_demo_nets)
    with pytest.raises(NonFiniteLossError, match=r"generator step 0 .*critic|generator step 0 .*bce"):
        _fit(task, _batches(nan=True), steps=1)


def test_nonfinite_loss_can_skip_steps(completion_demo_nets):
    task = CompletionTask(nets=completion_demo_nets, on_nonfinite="skip")
    before = {k: v.clone() for k, v in task.generator.state_dict().items()}
    _fit(task, _batches(n=2, nan=True), steps=2)
    assert task.skipped_steps >= 2
    after = task.generator.state_dict()
    assert all(torch.equal(before[k], after[k]) for k in before), "a skipped step must not update the generator"


def test_adversarial_warmup_skips_critic_updates(completion_demo_nets):
    task = CompletionTask(nets=completion_demo_nets, adversarial={"start_epoch": 1})
    _fit(task, _batches(n=2), steps=2)
    opt_g, opt_d = task.optimizers()
    assert not opt_d.optimizer.state, "critic must not step during warm-up"
    assert {int(s["step"]) for s in opt_g.optimizer.state.values()} == {2}


def test_summary_rows_on_meta_device_paper_scale(completion_paper_nets, completion_demo_nets):
    with torch.device("meta"):
        rows = CompletionTask.summary_rows({"nets": completion_paper_nets})
    gen = next(r for r in rows if r["component"] == "generator")
    assert tuple(gen["input"]) == (1, 1, 64, 64, 64) and tuple(gen["output"]) == (1, 1, 256, 256, 256)
    assert gen["params"] > 100_000_000
    assert completion_demo_nets["out_res"] == 64


def test_stage_bce_is_weighted_bce_of_the_pooled_target(completion_demo_nets):
    from lit3d.completion.losses import weighted_bce_with_logits

    task = CompletionTask(nets=completion_demo_nets, loss={"stage_weight": 0.5})
    g = torch.Generator().manual_seed(1)
    target = (torch.rand(2, 1, 64, 64, 64, generator=g) < 0.1).float()
    logits = [torch.randn(2, 1, 16, 16, 16, generator=g) for _ in range(2)]
    # hand-pooled: a coarse voxel is occupied when any of its 4^3 cell is
    small = (target.reshape(2, 1, 16, 4, 16, 4, 16, 4).amax(dim=(3, 5, 7)))
    want = (weighted_bce_with_logits(logits[0], small, 0.35) + weighted_bce_with_logits(logits[1], small, 0.35)) / 2
    assert torch.allclose(task._stage_bce(logits, target), want)


# ---------------------------------------------------------------- the prior baseline, a checkpoint buffer
class _Items(torch.utils.data.Dataset):
    def __init__(self, items: list[dict]):
        self.items = items

    def __len__(self) -> int:
        return len(self.items)

    def __getitem__(self, i: int) -> dict:
        return self.items[i]


class _Data(pl.LightningDataModule):
    """Training items with distinct targets (shuffled loader, like the real one); counts the
    training-data walks; ``forbid_train``: any walk of the training data fails the test."""

    def __init__(self, n: int = 6, forbid_train: bool = False):
        super().__init__()
        g = torch.Generator().manual_seed(3)
        self.items = []
        for i in range(n):
            target = (torch.rand(1, 64, 64, 64, generator=g) < 0.05 * (i + 1)).float()
            self.items.append({"input": torch.nn.functional.max_pool3d(target, 4), "target": target,
                               "label": torch.tensor(i % 4), "category": "chair"})
        self.forbid_train, self.train_walks = forbid_train, 0

    def train_dataloader(self) -> DataLoader:
        assert not self.forbid_train, "evaluation walked the training data"
        self.train_walks += 1
        return DataLoader(_Items(self.items), batch_size=2, shuffle=True)

    def test_dataloader(self) -> DataLoader:
        return DataLoader(_Items(self.items[:2]), batch_size=2)


def _trainer(**kw) -> pl.Trainer:
    return pl.Trainer(accelerator="cpu", logger=False, enable_checkpointing=False, enable_progress_bar=False,
                      enable_model_summary=False, **kw)


def _first_targets_mean(data: _Data, n: int) -> torch.Tensor:
    return torch.stack([it["target"] for it in data.items[:n]]).mean(0, keepdim=True)


@pytest.fixture(scope="module")
def fitted_checkpoint(tmp_path_factory, completion_demo_nets):
    """A demo-size task fitted one step (prior_samples=3 of 6 training items), saved as a checkpoint."""
    task = CompletionTask(nets=completion_demo_nets, prior_samples=3, adversarial={"start_epoch": 1})
    data = _Data()
    trainer = _trainer(max_epochs=1, limit_train_batches=1, limit_val_batches=0)
    trainer.fit(task, datamodule=data)
    path = tmp_path_factory.mktemp("ckpt") / "fitted.ckpt"
    trainer.save_checkpoint(path)
    return path, task.prior.clone(), data


def test_prior_is_the_mean_of_the_first_training_items_computed_at_fit_start(fitted_checkpoint):
    _, prior, data = fitted_checkpoint
    # items 0..2 in index order (not a shuffled draw): the same prior on every rank and in every run
    assert torch.equal(prior, _first_targets_mean(data, 3))
    assert data.train_walks == 2  # one for the prior (at fit start), one for training


def test_computing_the_prior_draws_no_global_random_numbers():
    from lit3d.completion.prior import mean_training_target

    data = _Data()
    before = torch.get_rng_state()
    prior, n = mean_training_target(_Items(data.items), 4, batch_size=3)
    assert torch.equal(torch.get_rng_state(), before)
    assert n == 4 and torch.equal(prior, _first_targets_mean(data, 4))
    assert mean_training_target(_Items([]), 4) == (None, 0)


def test_loaded_checkpoint_evaluates_with_its_saved_prior_without_walking_training_data(fitted_checkpoint):
    path, prior, _ = fitted_checkpoint
    assert {"prior", "prior_items"} <= set(torch.load(path, weights_only=True)["state_dict"])
    task = CompletionTask.load_from_checkpoint(path, map_location="cpu", weights_only=True)
    assert torch.equal(task.prior, prior) and int(task.prior_items) == 3
    _trainer(limit_test_batches=1).test(task, datamodule=_Data(forbid_train=True))
    assert torch.equal(task.prior, prior)


def test_checkpoint_without_prior_loads_and_computes_it_once(fitted_checkpoint, tmp_path, caplog):
    path, prior, _ = fitted_checkpoint
    ckpt = torch.load(path, weights_only=True)
    del ckpt["state_dict"]["prior"], ckpt["state_dict"]["prior_items"]
    ckpt["hyper_parameters"]["nets"] = {**ckpt["hyper_parameters"]["nets"], "preset": "demo"}  # as before that change
    old = tmp_path / "old.ckpt"
    torch.save(ckpt, old)
    with caplog.at_level("INFO", logger="lit3d.completion"):
        task = CompletionTask.load_from_checkpoint(old, map_location="cpu", weights_only=True)
        assert int(task.prior_items) == 0
        data = _Data()
        _trainer(limit_test_batches=1).test(task, datamodule=data)
    assert "checkpoint without the occupancy prior" in caplog.text
    assert data.train_walks == 1 and int(task.prior_items) == 3
    assert torch.equal(task.prior, prior)
