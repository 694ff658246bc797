"""Loss-weight phases (thesis 5.3.1) as a Lightning Callback.

Thesis schedule over 800 epochs: epochs 0-99 alpha=10, beta=1000; 100-299
alpha=1000, beta=1000; 300-799 alpha=1000, beta=100. A phase list gives each
phase's start either in epochs (int >= 1 or ``unit="epochs"``) or as a fraction
of ``trainer.max_epochs`` (``unit="fraction"``), so the schedule scales with the
run length:

    phases = [{"start": 0.0, "alpha": 10, "beta": 1000},
              {"start": 0.125, "alpha": 1000, "beta": 1000},
              {"start": 0.375, "alpha": 1000, "beta": 100}]

At ``on_train_epoch_start`` the callback sets ``pl_module.loss_alpha`` and
``pl_module.loss_beta`` from ``trainer.current_epoch`` and logs them
(``train/alpha``, ``train/beta``, ``train/phase``); ``on_train_start`` sets them too, for a
run resumed mid-epoch (Lightning skips ``on_train_epoch_start`` of that epoch). Its state (the
phase list, unit and last applied phase) is saved in checkpoints and restored on resume.
"""
from __future__ import annotations

from collections.abc import Sequence

import lightning.pytorch as pl

THESIS_PHASES = (
    {"start": 0, "alpha": 10.0, "beta": 1000.0},
    {"start": 100, "alpha": 1000.0, "beta": 1000.0},
    {"start": 300, "alpha": 1000.0, "beta": 100.0},
)
THESIS_EPOCHS = 800
THESIS_FRACTIONS = tuple({**p, "start": p["start"] / THESIS_EPOCHS} for p in THESIS_PHASES)


def phase_starts(phases: Sequence[dict], unit: str, max_epochs: int | None) -> list[int]:
    """Start epoch of each phase. ``unit``: "epochs" or "fraction" (of ``max_epochs``, rounded; each
    later phase starts at least one epoch after the one before, so none is skipped in a short run)."""
    if unit == "epochs":
        return [int(p["start"]) for p in phases]
    if unit != "fraction":
        raise ValueError(f"loss phase unit must be 'epochs' or 'fraction', got '{unit}'")
    if not max_epochs or max_epochs < 0:
        raise ValueError("loss phases given as fractions need trainer.max_epochs > 0")
    starts = []
    for i, p in enumerate(phases):
        s = int(round(float(p["start"]) * max_epochs))
        if i and float(p["start"]) > float(phases[i - 1]["start"]):
            s = max(s, starts[-1] + 1)  # a short run still gives every phase an epoch (4 epochs: 0, 1, 2)
        starts.append(s)
    return starts


def phase_at(epoch: int, phases: Sequence[dict], unit: str = "epochs", max_epochs: int | None = None) -> int:
    """Index of the phase that holds at ``epoch`` (the last one whose start <= epoch)."""
    starts = phase_starts(phases, unit, max_epochs)
    idx = 0
    for i, s in enumerate(starts):
        if epoch >= s:
            idx = i
    return idx


class LossPhases(pl.Callback):
    """Sets ``pl_module.loss_alpha`` / ``loss_beta`` per epoch from a phase list."""

    def __init__(self, phases: Sequence[dict] = THESIS_FRACTIONS, unit: str = "fraction"):
        if not phases:
            raise ValueError("LossPhases needs at least one phase")
        self.phases = [{"start": p["start"], "alpha": float(p["alpha"]), "beta": float(p["beta"])} for p in phases]
        starts = [float(p["start"]) for p in self.phases]
        if starts != sorted(starts):
            raise ValueError(f"loss phase starts must be increasing, got {starts}")
        self.unit = unit
        self.current_phase = -1
        self.last_epoch = -1

    def weights_at(self, epoch: int, max_epochs: int | None) -> tuple[int, float, float]:
        i = phase_at(epoch, self.phases, self.unit, max_epochs)
        return i, self.phases[i]["alpha"], self.phases[i]["beta"]

    def apply(self, trainer: pl.Trainer, pl_module: pl.LightningModule) -> None:
        i, a, b = self.weights_at(trainer.current_epoch, trainer.max_epochs)
        pl_module.loss_alpha, pl_module.loss_beta = a, b
        self.current_phase, self.last_epoch = i, trainer.current_epoch

    def on_train_start(self, trainer, pl_module) -> None:
        # a run resumed mid-epoch does not get on_train_epoch_start for that epoch (Lightning):
        # without this its remaining batches would use the module's constant alpha/beta
        self.apply(trainer, pl_module)

    def on_train_epoch_start(self, trainer, pl_module) -> None:
        self.apply(trainer, pl_module)
        pl_module.log_dict({"train/alpha": pl_module.loss_alpha, "train/beta": pl_module.loss_beta,
                            "train/phase": float(self.current_phase)}, on_step=False, on_epoch=True)

    def state_dict(self) -> dict:
        return {"phases": [dict(p) for p in self.phases], "unit": self.unit,
                "current_phase": self.current_phase, "last_epoch": self.last_epoch}

    def load_state_dict(self, state_dict: dict) -> None:
        self.phases = [dict(p) for p in state_dict["phases"]]
        self.unit = state_dict["unit"]
        self.current_phase = int(state_dict["current_phase"])
        self.last_epoch = int(state_dict["last_epoch"])
