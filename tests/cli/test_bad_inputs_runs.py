"""Reliability, beyond the table of :mod:`test_bad_inputs`: ``--debug`` and
``HYDRA_FULL_ERROR`` show the traceback, ``skip_bad`` skips and counts a bad file, and a run or data
folder that cannot be written (a file, under a file, read-only) or a misspelt split is refused with
one line before any work.
"""
from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

from datamodules.quality.mos import MosDataError
from lit3d.cli.common import run_cli
from lit3d.render.convert import ShapeError
from tests.helpers.bad_files import write_depth_cache
from tests.helpers.runs import BIN, REPO
from tests.helpers.entry_points import Ctx, data_cli, eval_cli, train_cli
from tests.helpers.files import liris_epfl


# ----------------------------------------------------------------------------- tracebacks on request
def test_debug_shows_the_traceback(tmp_path):
    env = {k: v for k, v in os.environ.items() if k != "HYDRA_FULL_ERROR"}
    res = subprocess.run([str(BIN / "lit3d-train"), "--debug", "experiment=canonical_tosca",
                          f"hydra.run.dir={tmp_path}/run"], cwd=REPO, env=env, capture_output=True, text=True,
                         timeout=120)
    assert res.returncode == 1, res.stderr
    assert "Traceback" in res.stderr and "UserError: missing value for data.root" in res.stderr


def test_hydra_full_error_and_score_debug_raise_in_process(tmp_path, monkeypatch):
    from lit3d.runtime.errors import UserError
    from lit3d.cli.score import main as score_main
    from lit3d.cli.train import main as train_main

    monkeypatch.setenv("HYDRA_FULL_ERROR", "1")
    monkeypatch.setattr(sys, "argv", ["lit3d-train", "experiment=nope"])
    with pytest.raises(UserError, match="experiment=nope"):
        train_main()
    monkeypatch.delenv("HYDRA_FULL_ERROR")
    monkeypatch.setattr(sys, "argv", ["lit3d-train", "--debug", "task=nope"])
    with pytest.raises(UserError, match="task=nope"):
        train_main()
    (tmp_path / "e.obj").write_bytes(b"")
    with pytest.raises(ShapeError, match="empty file"):
        score_main([str(tmp_path / "e.obj"), str(tmp_path / "e.obj"), "--debug"])


# ----------------------------------------------------------------------------- skip_bad
def test_skip_bad_depth_image_is_skipped_and_counted(tmp_path, caplog):
    dm = write_depth_cache(tmp_path / "cache", lambda d, m: (np.where(m, np.nan, 0).astype(np.float16), m),
                           skip_bad=True)
    with caplog.at_level("WARNING", logger="lit3d"):
        dm.setup()
    info = dm.describe()
    assert info["skipped_bad_files"] == 1 and info["subjects"] == 3
    assert "s1.npz: depth_1_0: depth image contains NaN or inf" in caplog.text
    used = {(r["subject"], r["pose"]) for split in dm.splits.values() for r in split}
    assert ("s1", 1) not in used and {("s0", 1), ("s2", 1)} & used


def test_skip_bad_mos_row_naming_a_missing_mesh(tmp_path):
    from datamodules.quality import QualityDataModule

    root = liris_epfl(tmp_path / "liris", missing={"Dyno_noise_2"})
    strict = QualityDataModule(str(tmp_path / "data"), source="liris_epfl", root=str(root))
    with pytest.raises(MosDataError, match="Dyno_noise_2"):
        strict._real_pairs()
    dm = QualityDataModule(str(tmp_path / "data"), source="liris_epfl", root=str(root), skip_bad=True)
    with pytest.warns(UserWarning, match=r"Dyno_noise_2.*\(skipped\)"):
        pairs, _ = dm._real_pairs()
    assert len(pairs) == 7 and len(dm.skipped) == 1 and "no mesh file named 'Dyno_noise_2'" in dm.skipped[0]


# ----------------------------------------------------------------------------- unwritable outputs
HYDRA_MAINS = {"lit3d-train": train_cli, "lit3d-eval": eval_cli, "lit3d-data": data_cli}


@pytest.mark.parametrize("fault", ["run-dir-under-a-file", "run-dir-is-a-file", "run-dir-read-only",
                                   "data-dir-is-a-file", "data-dir-read-only"])
@pytest.mark.parametrize("prog", sorted(HYDRA_MAINS))
def test_unwritable_run_or_data_dir_is_one_line_before_any_work(prog, fault, tmp_path, readonly_dir, capsys,
                                                                 monkeypatch):
    """hydra.run.dir / data.data_dir that is a file, lies under one, or is read-only: exit 2 and
    one line naming the path, before Hydra creates anything; the file is left as it was."""
    if prog == "lit3d-eval" and fault.startswith("data"):
        pytest.skip("lit3d-eval takes its data config from the checkpoint")
    monkeypatch.delenv("HYDRA_FULL_ERROR", raising=False)
    a_file = tmp_path / "a_file"
    a_file.write_text("mine")
    bad = {"run-dir-under-a-file": a_file / "run", "run-dir-is-a-file": a_file,
           "run-dir-read-only": readonly_dir / "run", "data-dir-is-a-file": a_file,
           "data-dir-read-only": readonly_dir / "data"}[fault]
    key = "hydra.run.dir" if fault.startswith("run") else "data.data_dir"
    args = [f"{key}={bad}"] + ([] if key == "hydra.run.dir" else [f"hydra.run.dir={tmp_path}/run"])
    if prog != "lit3d-eval":
        args.insert(0, "experiment=completion_demo")
    out = HYDRA_MAINS[prog](" ".join(args), Ctx(tmp_path, capsys, monkeypatch, None))
    lines = [ln for ln in out.err.splitlines() if ln.strip()]
    assert out.code == 2 and len(lines) == 1, out
    assert lines[0].startswith(f"error: {bad}: {key}") and "Traceback" not in out.err, lines
    assert a_file.read_text() == "mine" and not (tmp_path / "run").exists()
    assert not any(readonly_dir.iterdir())


def test_misspelt_split_touches_no_cache(tmp_path, compose_cfg, capsys):
    """``+data.sizes.trian=10`` (the form Hydra's own hint suggests) is refused before the data
    folder is created or a cache hash is computed."""
    from lit3d.cli.data import prepare

    cfg = compose_cfg(["experiment=completion_demo", "+data.sizes.trian=10"])
    with pytest.raises(SystemExit) as info:
        run_cli(prepare, cfg)
    err = capsys.readouterr().err.strip().splitlines()
    assert info.value.code == 2 and len(err) == 1 and "data.sizes.trian: unknown split" in err[0], err
    assert not (tmp_path / "data").exists()


def test_zero_epochs_writes_no_test_results(tmp_path, compose_cfg, capsys):
    """trainer.max_epochs=0 is refused before anything is built: no metrics.json of untrained weights."""
    from lit3d.cli.train import train

    cfg = compose_cfg(["experiment=completion_demo", "logger=none", "trainer.max_epochs=0"])
    with pytest.raises(SystemExit) as info:
        run_cli(train, cfg)
    err = capsys.readouterr().err.strip().splitlines()
    assert info.value.code == 2 and len(err) == 1 and err[0].startswith("error: trainer.max_epochs=0:"), err
    assert not (tmp_path / "run").exists() and not (tmp_path / "data").exists()
