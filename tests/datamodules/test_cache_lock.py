"""Processes preparing one data folder at once (the jobs of a multirun) take turns: the first one
prepares it, the others wait on ``CacheBuilder.locked()`` and then find the cache complete."""
from __future__ import annotations

import fcntl
import json
import multiprocessing as mp
import os
from pathlib import Path

import pytest

from datamodules.cache import LOCK, MANIFEST, CacheBuilder

SIZES = {"train": 8, "val": 4, "test_same": 4, "test_cross": 4, "test_unseen": 4}


def _tiny(data_dir: Path):
    from datamodules.completion import CompletionDataModule

    return CompletionDataModule(data_dir=str(data_dir), target_res=16, input_factor=4, sizes=SIZES,
                                prepare={"progress": False})


def _prepare_counting(data_dir: str, barrier, out) -> None:
    """A spawned process: prepare ``data_dir`` right after the other one is ready too; report how
    many items this process wrote itself."""
    os.environ["OMP_NUM_THREADS"] = "1"
    import datamodules.completion.sources as sources

    written = []
    save_pair = sources.save_pair

    def counting(path, *args, **kwargs):
        written.append(str(path))
        return save_pair(path, *args, **kwargs)

    sources.save_pair = counting
    dm = _tiny(Path(data_dir))
    barrier.wait(timeout=300)
    try:
        dm.prepare_data()
        out.put((os.getpid(), len(written), None))
    except BaseException as exc:  # reported to the test
        out.put((os.getpid(), len(written), f"{type(exc).__name__}: {exc}"))


def test_two_processes_preparing_one_folder_take_turns(tmp_path):
    ctx = mp.get_context("spawn")
    barrier, out = ctx.Barrier(2), ctx.Queue()
    data = tmp_path / "shared"
    procs = [ctx.Process(target=_prepare_counting, args=(str(data), barrier, out)) for _ in range(2)]
    for p in procs:
        p.start()
    results = [out.get(timeout=600) for _ in procs]
    for p in procs:
        p.join(timeout=60)
    assert [r[2] for r in results] == [None, None], results
    assert all(p.exitcode == 0 for p in procs)

    ref = _tiny(tmp_path / "alone")
    ref.prepare_data()
    n_items = len(ref._builder().manifest()["items"])
    # one process made every item; the other waited and found the cache complete
    assert sorted(r[1] for r in results) == [0, n_items], results
    shared = _tiny(data)._builder()
    assert shared.is_complete()
    assert shared.manifest()["manifest_hash"] == ref._builder().manifest()["manifest_hash"]
    assert not list(data.rglob("*.tmp"))


def test_the_lock_is_released_on_errors_and_reentrant(tmp_path):
    b = CacheBuilder(tmp_path / "c", "gen", "1", {"a": 1})
    with pytest.raises(RuntimeError), b.locked():
        with b.locked():  # the same thread again: no deadlock
            pass
        raise RuntimeError("preparation failed")
    with open(tmp_path / "c" / LOCK) as f:  # free again: another open file can take it at once
        fcntl.flock(f.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        fcntl.flock(f.fileno(), fcntl.LOCK_UN)
    # the lock file is no item of unknown origin and does not spoil a preparation
    with b.locked():
        b.begin()
        (tmp_path / "c" / "items").mkdir()
        (tmp_path / "c" / "items" / "x.bin").write_bytes(b"x")
        b.finish([{"file": "items/x.bin"}])
    assert b.is_complete() and json.loads((tmp_path / "c" / MANIFEST).read_text())["items"][0]["file"] == "items/x.bin"
