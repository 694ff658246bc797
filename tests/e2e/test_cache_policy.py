"""Prepared caches are keyed by their config and checked on load.

Real ``lit3d-data`` / ``lit3d-eval`` / ``lit3d-train`` processes on a tiny completion set:

- a folder holding another config's data is refused by every entry point, ``lit3d-eval``
  included, with one line naming what differs; nothing is deleted; ``lit3d-data --rebuild``
  alone replaces it;
- a hand-edited manifest (items dropped, a ``val`` item relabelled ``train``) and a truncated
  item are detected and repaired by the next preparation (same manifest hash as before);
- a training whose ``data_dir`` another process re-prepares stops with one line saying so.
"""
from __future__ import annotations

import json
import signal
import subprocess
import time
from pathlib import Path

import pytest
from tests.helpers.runs import BIN, REPO, child_env, start_script

from datamodules.cache import MANIFEST, DataError
from lit3d.runtime.build import build_datamodule
from tests.helpers.runs import TINY_NETS

SIZES = "data.sizes={train:4,val:2,test_same:2,test_cross:2,test_unseen:2}"
DATA = ["experiment=completion_demo", SIZES, "data.prepare.progress=false"]


def _run(args: list[str], timeout: float = 180) -> subprocess.CompletedProcess:
    return subprocess.run([str(BIN / args[0]), *args[1:]], cwd=REPO, env=child_env(), capture_output=True, text=True,
                          timeout=timeout)


def _one_error(res: subprocess.CompletedProcess) -> str:
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert res.returncode == 2 and "Traceback" not in res.stderr, res.stderr[-3000:]
    assert [ln for ln in lines if ln.startswith("error:")] == lines[-1:], res.stderr[-3000:]
    return lines[-1]


def _snapshot(root: Path) -> dict[str, tuple[int, int]]:
    return {str(p.relative_to(root)): (p.stat().st_size, p.stat().st_mtime_ns) for p in sorted(root.rglob("*"))
            if p.is_file() and p.name != ".lock"}


def _prepare(tmp_path: Path, *extra: str) -> subprocess.CompletedProcess:
    res = _run(["lit3d-data", *DATA, f"paths.data_dir={tmp_path}/data", f"paths.log_dir={tmp_path}/logs", *extra])
    assert res.returncode == 0, res.stderr[-3000:]
    return res


def _described(res: subprocess.CompletedProcess) -> dict:
    """The JSON that lit3d-data prints on stdout (its log lines go to stderr)."""
    lines = res.stdout.splitlines()
    return json.loads("\n".join(lines[lines.index("{"):]))


def test_another_configs_cache_is_refused_by_every_entry_point(tmp_path):
    from lit3d.api.checkpoints import untrained_checkpoint

    cache = tmp_path / "data" / "completion_demo"
    _prepare(tmp_path)
    before = _snapshot(cache)
    ckpt = untrained_checkpoint("completion_demo", tmp_path / "c.ckpt", TINY_NETS)
    # the case: an evaluation naming a prepared folder with other data settings (here the seed)
    line = _one_error(_run(["lit3d-eval", f"ckpt_path={ckpt}", "data=completion_synth", f"data.data_dir={cache}",
                            "data.target_res=64", "data.render.sensor=recgan", SIZES, "data.prepare.progress=false", "seed=7",
                            f"hydra.run.dir={tmp_path}/runs/eval"]))
    assert line == (f"error: {cache}: holds data prepared with another config (seed: 7 here, 42 there); nothing was "
                    "deleted: to replace it run lit3d-data with this run's overrides plus --rebuild, or set "
                    "data.data_dir to another folder")
    assert _snapshot(cache) == before, "a refused run changed the cache"
    res = _prepare(tmp_path, "seed=7", "--rebuild")
    assert "--rebuild: deleting the prepared items" in res.stderr  # log lines go to stderr: stdout holds the JSON summary alone
    assert json.loads((cache / MANIFEST).read_text())["config"]["seed"] == 7


def test_hand_edited_manifest_and_truncated_item_are_found_and_repaired(tmp_path, compose_cfg):
    cache = tmp_path / "data" / "completion_demo"
    first = _described(_prepare(tmp_path))
    manifest = json.loads((cache / MANIFEST).read_text())
    train = [it for it in manifest["items"] if it["split"] == "train"]
    edited = [it for it in manifest["items"] if it not in train[:2]]
    next(it for it in edited if it["split"] == "val")["split"] = "train"
    (cache / MANIFEST).write_text(json.dumps({**manifest, "items": edited}))
    dm = build_datamodule(compose_cfg(DATA, data_dir=tmp_path / "data").data)
    with pytest.raises(DataError, match=r"manifest.json was edited: its items no longer match its manifest_hash"):
        dm.setup()  # loading without preparing: named, not trusted
    res = _prepare(tmp_path)
    assert "manifest.json was edited" in res.stderr and "repairing" in res.stderr
    again = _described(res)
    assert again["split_sizes"] == first["split_sizes"] and again["manifest_hash"] == first["manifest_hash"]

    victim = cache / train[0]["file"]
    good = victim.read_bytes()
    victim.write_bytes(good[: len(good) // 2])
    res = _prepare(tmp_path)
    assert f"{train[0]['file']}: {len(good) // 2} bytes, the manifest says {len(good)}" in res.stderr
    assert victim.read_bytes() == good and _described(res)["manifest_hash"] == first["manifest_hash"]


@pytest.mark.slow  # default suite under 10 min; runs in make test-all
def test_training_stops_when_another_process_re_prepares_its_data(tmp_path):
    run, data = tmp_path / "run", f"paths.data_dir={tmp_path}/data"
    common = ["experiment=completion_demo", "data.sizes={train:8,val:4,test_same:4,test_cross:4,test_unseen:4}",
              "data.batch_size=4", "data.prepare.progress=false", *TINY_NETS, "logger=none", "callbacks.progress_bar=null",
              "test_after_fit=false", data]
    proc = start_script(["lit3d-train", *common, "trainer.max_epochs=500", f"hydra.run.dir={run}"], tmp_path / "train")
    try:
        last, t0 = run / "checkpoints" / "last.ckpt", time.monotonic()
        while not last.is_file():  # the first epoch is done
            assert proc.poll() is None, (tmp_path / "train.err").read_text()[-3000:]
            assert time.monotonic() - t0 < 180, "training did not get going"
            time.sleep(0.3)
        res = _run(["lit3d-data", *common, "seed=7", f"hydra.run.dir={tmp_path}/runs/rebuild", "--rebuild"])
        assert res.returncode == 0, res.stderr[-3000:]
        assert proc.wait(timeout=120) == 2
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.SIGKILL)
            proc.wait(timeout=60)
    err = (tmp_path / "train.err").read_text()
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert "Traceback" not in err and lines[-1].startswith(f"error: {tmp_path}/data/completion_demo"), err[-3000:]
    assert ("changed while this run read" in lines[-1] or "was removed while this run read" in lines[-1]), lines[-1]
