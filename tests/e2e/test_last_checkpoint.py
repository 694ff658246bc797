"""``last.ckpt`` always holds the newest state, also after the run dir moved.

Real ``lit3d-train`` runs (canonical task, tiny nets). The monitored value is the epoch itself
with ``mode=min``, so the first epoch stays the best: the case where Lightning's
``ModelCheckpoint(save_last=True)`` stopped writing ``last`` (it writes it only with a top-k
save) and ``ckpt_path=last`` redid the later epochs. Then the run dir is moved and resumed:
the resumed run writes ``last.ckpt`` (no ``last-v1.ckpt``), keeps its best checkpoint (now in
the new folder), so the next ``ckpt_path=last`` starts from the newest state.
"""
from __future__ import annotations

import shutil
import subprocess

from tests.helpers.runs import BIN, CANONICAL, CANONICAL_STEPS_PER_EPOCH, REPO, child_env, load_checkpoint

FLAT = [a for a in CANONICAL if "limit_val_batches" not in a] + [
    "+trainer.limit_val_batches=1", "trainer.check_val_every_n_epoch=1", "task_info.monitor=epoch", "task_info.monitor_mode=min",
    "logger=none"]


def _train(*args: str) -> None:
    res = subprocess.run([str(BIN / "lit3d-train"), *FLAT, *args], cwd=REPO, env=child_env(), capture_output=True,
                         text=True, timeout=300)
    assert res.returncode == 0, res.stderr[-3000:]


def test_last_is_the_newest_state_with_a_flat_metric_and_after_a_move(tmp_path):
    run = tmp_path / "run"
    data = f"paths.data_dir={tmp_path}/data"
    _train(data, f"hydra.run.dir={run}", "trainer.max_epochs=3")
    last = load_checkpoint(run / "checkpoints" / "last.ckpt")
    assert last["global_step"] == 3 * CANONICAL_STEPS_PER_EPOCH, "last.ckpt lags behind the run"
    assert sorted(p.name for p in (run / "checkpoints").iterdir()) == ["best-000.ckpt", "last.ckpt"]

    moved = tmp_path / "moved"
    shutil.move(run, moved)
    _train(data, f"hydra.run.dir={moved}", "trainer.max_epochs=4", "ckpt_path=last")
    names = sorted(p.name for p in (moved / "checkpoints").iterdir())
    assert names == ["best-000.ckpt", "last.ckpt"], names  # no last-v1.ckpt, no second "best" after the move
    last = load_checkpoint(moved / "checkpoints" / "last.ckpt")
    assert last["global_step"] == 4 * CANONICAL_STEPS_PER_EPOCH
    state = next(v for k, v in last["callbacks"].items() if k.startswith("ModelCheckpoint"))
    assert state["best_model_path"] == str((moved / "checkpoints" / "best-000.ckpt").resolve())
    assert state["last_model_path"] == str((moved / "checkpoints" / "last.ckpt").resolve())
    assert float(state["best_model_score"]) == 0.0  # restored, not restarted at the resumed epoch
