"""The completion epoch metrics under DDP: a process that saw no batch of a split computes (and
syncs) with the others instead of skipping, so nobody waits; one process skips an unused metric
without torchmetrics' "compute called before update" warning."""
from __future__ import annotations

import json
import sys
import warnings
from datetime import timedelta
from pathlib import Path

import torch
import torch.multiprocessing as mp

from lit3d.completion.split_metrics import split_values
from lit3d.metrics.gathered import compute_if_updated
from lit3d.metrics.voxel import VoxelSweepMetrics, default_thresholds

CATS = ["chair", "table"]
SPLITS, SOURCES = ("same", "unseen"), ("model", "input")
THRESHOLDS = {"model": 0.4, "input": 0.5}


def _metrics() -> dict[str, VoxelSweepMetrics]:
    return {f"{sp}_{s}": VoxelSweepMetrics(CATS) for sp in SPLITS for s in SOURCES}


def _update(metrics: dict[str, VoxelSweepMetrics], seed: int) -> None:
    """Two batches of the "same" split; none of "unseen"."""
    g = torch.Generator().manual_seed(seed)
    for _ in range(2):
        target = (torch.rand(2, 1, 4, 4, 4, generator=g) > 0.5).float()
        cats = torch.tensor([0, 1])
        for s in SOURCES:
            metrics[f"same_{s}"].update(torch.rand(2, 1, 4, 4, 4, generator=g), target, cats)


def _worker(rank: int, world: int, init_file: str, out_dir: str) -> None:
    import torch.distributed as dist

    dist.init_process_group("gloo", init_method=f"file://{init_file}", rank=rank, world_size=world,
                            timeout=timedelta(seconds=60))  # a mismatched collective fails instead of hanging
    torch.set_num_threads(1)
    metrics = _metrics()
    if rank == 0:  # rank 1 sees no batch at all
        _update(metrics, seed=0)
    values = split_values(metrics, SPLITS, SOURCES, THRESHOLDS, default_thresholds().float(), CATS)
    dist.barrier()
    dist.destroy_process_group()
    Path(out_dir, f"{rank}.json").write_text(json.dumps(values))


def test_a_process_without_batches_computes_with_the_others(tmp_path):
    if sys.platform == "win32":  # pragma: no cover
        return
    mp.spawn(_worker, args=(2, str(tmp_path / "init"), str(tmp_path)), nprocs=2, join=True)
    got = [json.loads((tmp_path / f"{r}.json").read_text()) for r in range(2)]
    one = _metrics()
    _update(one, seed=0)  # the same batches in one process
    expected = split_values(one, SPLITS, SOURCES, THRESHOLDS, default_thresholds().float(), CATS)
    assert "test/same/iou" in expected and not any("unseen" in k for k in expected)
    assert got[0].keys() == got[1].keys() == expected.keys()
    for k, v in expected.items():
        assert abs(got[0][k] - v) < 1e-9 and abs(got[1][k] - v) < 1e-9, k


def test_an_unused_metric_is_skipped_quietly_on_one_process():
    metric = VoxelSweepMetrics(CATS)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert compute_if_updated(metric) is None
    metric.update(torch.ones(1, 1, 2, 2, 2), torch.ones(1, 1, 2, 2, 2), torch.tensor([0]))
    assert float(compute_if_updated(metric)["iou"][0]) == 1.0
