"""A non-finite loss on one DDP rank makes every rank skip (or raise at) the same step."""
from __future__ import annotations

import json
import sys
from pathlib import Path

import torch
import torch.multiprocessing as mp


class _Module:
    skipped_steps = 0

    def print(self, *a, **k):
        pass


def _worker(rank: int, world: int, init_file: str, out_dir: str) -> None:
    import torch.distributed as dist

    from lit3d.callbacks.nonfinite import NonFiniteLossError, guard_step

    dist.init_process_group("gloo", init_method=f"file://{init_file}", rank=rank, world_size=world)
    torch.set_num_threads(1)
    m = _Module()
    decisions = []
    for step in range(4):
        nan = rank == 1 and step in (1, 3)  # only rank 1 sees NaNs
        loss = torch.tensor(float("nan") if nan else 1.0)
        decisions.append(guard_step(m, {"loss": loss}, f"step {step}", "skip"))
    try:
        guard_step(m, {"loss": torch.tensor(float("nan") if rank == 0 else 1.0)}, "step 4", "raise")
        raised = ""
    except NonFiniteLossError as e:
        raised = str(e)
    dist.barrier()
    dist.destroy_process_group()
    Path(out_dir, f"{rank}.json").write_text(json.dumps({"decisions": decisions, "skipped": m.skipped_steps,
                                                         "raised": raised}))


def test_skip_and_raise_are_decided_jointly_across_ranks(tmp_path):
    if sys.platform == "win32":  # pragma: no cover
        return
    mp.spawn(_worker, args=(2, str(tmp_path / "init"), str(tmp_path)), nprocs=2, join=True)
    got = [json.loads((tmp_path / f"{r}.json").read_text()) for r in range(2)]
    for g in got:
        assert g["decisions"] == [True, False, True, False] and g["skipped"] == 2
    assert "loss" in got[0]["raised"] and "on another process" in got[1]["raised"]
