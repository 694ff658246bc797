"""LossPhases: weights at each boundary (epochs and fractions) and after a checkpoint resume."""
from types import SimpleNamespace

import lightning.pytorch as pl
import pytest
import torch
from torch.utils.data import DataLoader, TensorDataset

from lit3d.canonical.loss_phases import THESIS_FRACTIONS, THESIS_PHASES, LossPhases, phase_at, phase_starts
from lit3d.canonical.losses import canonical_loss, mask_loss, masked_depth_loss


class _Mod(SimpleNamespace):
    def log_dict(self, *a, **k):
        pass


def _weights(cb, epoch, max_epochs):
    mod = _Mod()
    cb.on_train_epoch_start(SimpleNamespace(current_epoch=epoch, max_epochs=max_epochs), mod)
    return mod.loss_alpha, mod.loss_beta


@pytest.mark.parametrize("epoch,expected", [
    (0, (10, 1000)), (99, (10, 1000)), (100, (1000, 1000)), (299, (1000, 1000)),
    (300, (1000, 100)), (799, (1000, 100)),
])
def test_thesis_schedule_in_epochs(epoch, expected):
    assert _weights(LossPhases(THESIS_PHASES, unit="epochs"), epoch, 800) == expected


@pytest.mark.parametrize("epoch,expected", [
    (0, (10, 1000)), (0, (10, 1000)), (1, (1000, 1000)), (2, (1000, 1000)), (3, (1000, 100)), (7, (1000, 100)),
])
def test_fractions_scale_with_run_length(epoch, expected):
    # 8 epochs: starts at round(0.125 * 8) = 1 and round(0.375 * 8) = 3
    assert _weights(LossPhases(THESIS_FRACTIONS, unit="fraction"), epoch, 8) == expected


@pytest.mark.parametrize("max_epochs,starts", [(3, [0, 1, 2]), (4, [0, 1, 2]), (8, [0, 1, 3]), (30, [0, 4, 11])])
def test_short_runs_give_every_phase_an_epoch(max_epochs, starts):
    # 4 epochs used to round to [0, 0, 2]: the first (mask-first) phase never ran
    assert phase_starts(THESIS_FRACTIONS, "fraction", max_epochs) == starts
    assert _weights(LossPhases(THESIS_FRACTIONS, unit="fraction"), 0, max_epochs) == (10, 1000)


def test_fractions_at_thesis_length_equal_epoch_schedule():
    for e in range(800):
        assert phase_at(e, THESIS_FRACTIONS, "fraction", 800) == phase_at(e, THESIS_PHASES, "epochs")


def test_bad_phase_lists_are_rejected():
    with pytest.raises(ValueError):
        LossPhases([], unit="epochs")
    with pytest.raises(ValueError, match="increasing"):
        LossPhases([{"start": 5, "alpha": 1, "beta": 1}, {"start": 2, "alpha": 1, "beta": 1}], unit="epochs")
    with pytest.raises(ValueError, match="unit"):
        phase_at(0, THESIS_PHASES, "steps")


class _Tiny(pl.LightningModule):
    def __init__(self):
        super().__init__()
        self.lin = torch.nn.Linear(1, 1)
        self.seen: dict[int, tuple[float, float]] = {}
        self.loss_alpha = self.loss_beta = None

    def training_step(self, batch, idx):
        self.seen[self.current_epoch] = (self.loss_alpha, self.loss_beta)
        return self.lin(batch[0]).pow(2).mean()

    def configure_optimizers(self):
        return torch.optim.SGD(self.parameters(), lr=0.01)


def _fit(tmp_path, max_epochs, ckpt=None, phases=None):
    cb = LossPhases(phases or [{"start": 0, "alpha": 1, "beta": 2}, {"start": 2, "alpha": 3, "beta": 4},
                               {"start": 4, "alpha": 5, "beta": 6}], unit="epochs")
    mod = _Tiny()
    ckpt_cb = pl.callbacks.ModelCheckpoint(dirpath=tmp_path, save_last=True, save_top_k=-1, every_n_epochs=1,
                                           filename="e{epoch}", auto_insert_metric_name=False)
    tr = pl.Trainer(max_epochs=max_epochs, callbacks=[cb, ckpt_cb], logger=False, enable_progress_bar=False,
                    enable_model_summary=False, num_sanity_val_steps=0, accelerator="cpu")
    tr.fit(mod, DataLoader(TensorDataset(torch.ones(2, 1)), batch_size=2), ckpt_path=ckpt)
    return mod, cb


def test_resume_continues_in_the_right_phase(tmp_path):
    mod, cb = _fit(tmp_path, max_epochs=3)
    assert mod.seen == {0: (1, 2), 1: (1, 2), 2: (3, 4)}
    state = cb.state_dict()
    assert state["current_phase"] == 1 and state["last_epoch"] == 2
    ckpt = torch.load(tmp_path / "last.ckpt", weights_only=True)
    assert any("LossPhases" in k for k in ckpt["callbacks"])
    # resume with a *different* phase list in the config: the checkpoint's schedule wins
    other = [{"start": 0, "alpha": 100, "beta": 100}]
    mod2, cb2 = _fit(tmp_path, max_epochs=6, ckpt=str(tmp_path / "last.ckpt"), phases=other)
    assert mod2.seen == {3: (3, 4), 4: (5, 6), 5: (5, 6)}
    assert cb2.current_phase == 2


def test_state_dict_round_trip():
    cb = LossPhases(THESIS_FRACTIONS)
    _weights(cb, 5, 8)
    cb2 = LossPhases([{"start": 0, "alpha": 0, "beta": 0}], unit="epochs")
    cb2.load_state_dict(cb.state_dict())
    assert cb2.state_dict() == cb.state_dict()
    assert _weights(cb2, 2, 8) == (1000, 1000)


def test_losses_match_formulas():
    g = torch.Generator().manual_seed(0)
    dh, mh, d = (torch.rand(2, 1, 5, 5, generator=g) for _ in range(3))
    m = (torch.rand(2, 1, 5, 5, generator=g) > 0.5).float()
    assert masked_depth_loss(dh, mh, d, m).item() == pytest.approx((mh * m * (dh - d) ** 2).mean().item())
    assert mask_loss(mh, m).item() == pytest.approx(((mh - m) ** 2).mean().item())
    out = canonical_loss(dh, mh, d, m, alpha=10, beta=1000)
    assert out["loss"].item() == pytest.approx(10 * out["depth"].item() + 1000 * out["mask"].item(), rel=1e-6)
