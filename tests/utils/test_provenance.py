"""Runs record what made them: the lit3d version, the git commit and the data's manifest hash, in
every checkpoint (``checkpoint["lit3d"]["provenance"]``) and in every ``metrics.json``."""
from __future__ import annotations

import json
import shutil
import subprocess
import tomllib
from importlib import metadata
from pathlib import Path
from types import SimpleNamespace

import pytest
import torch
from omegaconf import open_dict

from lit3d.callbacks.metadata import MetadataCallback
from lit3d.utils import provenance as prov
from tests.helpers.paths import REPO

KEYS = {"lit3d_version", "git_commit", "git_dirty", "manifest_hash", "data_config_hash"}
# a quality run of a few seconds: 2 shapes x 2 distortions x 2 levels, 32 px renders of one style
QUALITY_RUN = [
    "experiment=quality_demo", "logger=none", "callbacks.progress_bar=null", "+trainer.enable_progress_bar=false",
    "data.synth.shapes=[blob,torus]", "+data.synth.distortions=[noise,taubin]", "data.synth.n_levels=2",
    "data.synth.subdivisions=2",
    "data.feature_tables.options={size:32,styles:[toon],measures:[mask_ssim,mse],n_samples:500}",
    "task.sfs.epochs=2", "task.sfs.max_features=2", "evaluation.cv=false", "trainer.max_epochs=2",
    "trainer.log_every_n_steps=1",
]


def _head() -> str | None:
    """The checkout's commit by git itself (None without git or a checkout)."""
    if shutil.which("git") is None or not (REPO / ".git").exists():
        return None
    return subprocess.run(["git", "-C", str(REPO), "rev-parse", "HEAD"], capture_output=True, text=True).stdout.strip()


def test_version_from_metadata_else_pyproject(monkeypatch, tmp_path):
    assert prov.lit3d_version() == metadata.version("lit3d")
    declared = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["version"]

    def not_installed(name):
        raise metadata.PackageNotFoundError(name)

    monkeypatch.setattr(prov.metadata, "version", not_installed)
    assert prov.lit3d_version() == declared
    assert prov.pyproject_version(tmp_path / "missing.toml") == prov.UNKNOWN_VERSION
    (tmp_path / "p.toml").write_text('[tool.x]\nversion = "9"\n\n[project]\nname = "x"\nversion = "1.2.3"\n')
    assert prov.pyproject_version(tmp_path / "p.toml") == "1.2.3"  # [project]'s, not another table's


def test_git_commit_only_in_a_checkout(monkeypatch, tmp_path):
    state = prov.git_state.__wrapped__  # uncached
    assert state(tmp_path) == (None, None)  # no .git here (as in a wheel's site-packages)
    head = _head()
    if head is not None:
        commit, dirty = state(REPO)
        assert commit == head and isinstance(dirty, bool)
    monkeypatch.setenv("PATH", str(tmp_path))  # git not installed
    assert state(REPO) == (None, None)


def test_metadata_callback_records_the_datamodule_manifest():
    cb = MetadataCallback({"name": "completion"}, {"source": "synth"}, "abc")
    trainer = SimpleNamespace(datamodule=SimpleNamespace(manifest={"manifest_hash": "m1", "config_hash": "c1"}))
    ckpt: dict = {}
    cb.on_save_checkpoint(trainer, None, ckpt)
    record = ckpt["lit3d"]["provenance"]
    assert set(record) == KEYS and ckpt["lit3d"]["wandb_id"] == "abc"
    assert (record["manifest_hash"], record["data_config_hash"]) == ("m1", "c1")
    assert record["lit3d_version"] == metadata.version("lit3d") and record["git_commit"] == _head()
    cb.on_save_checkpoint(None, None, ckpt)  # no trainer (lit3d.untrained_checkpoint): no data record
    assert ckpt["lit3d"]["provenance"]["manifest_hash"] is None


def test_train_and_eval_record_provenance(compose_cfg, tmp_path):
    from lit3d.runtime.build import build_datamodule
    from lit3d.cli.evaluate import evaluate
    from lit3d.cli.train import train

    cfg = compose_cfg(QUALITY_RUN)
    train(cfg)
    run = Path(cfg.paths.output_dir)
    manifest = build_datamodule(cfg.data).describe()["manifest_hash"]  # what lit3d-data prints
    assert isinstance(manifest, str) and len(manifest) >= 16
    want = {"lit3d_version": metadata.version("lit3d"), "git_commit": _head(), "manifest_hash": manifest}

    metrics = json.loads((run / "metrics.json").read_text())
    assert any(k.startswith("test/") for k in metrics)  # tested after fitting: run_evaluation wrote it
    assert set(metrics["provenance"]) == KEYS
    assert {k: metrics["provenance"][k] for k in want} == want
    ckpt = next((run / "checkpoints").glob("best-*.ckpt"))
    stored = torch.load(ckpt, map_location="cpu", weights_only=True)["lit3d"]["provenance"]
    assert stored == metrics["provenance"]

    eval_cfg = compose_cfg([f"ckpt_path={ckpt}", "n_figures=0"], config_name="eval", data_dir=Path(cfg.paths.data_dir))
    with open_dict(eval_cfg):
        eval_cfg.paths.output_dir = str(tmp_path / "eval")
    evaluate(eval_cfg)
    evaluated = json.loads((tmp_path / "eval" / "metrics.json").read_text())
    assert {k: evaluated["provenance"][k] for k in want} == want  # the same data, evaluated
    assert evaluated["provenance"]["checkpoint"] == stored and evaluated["ckpt_path"] == str(ckpt)


@pytest.mark.parametrize("present", [True, False])
def test_data_provenance_of_a_datamodule_not_set_up(present):
    dm = SimpleNamespace(manifest={"manifest_hash": "h", "config_hash": "c"}) if present else SimpleNamespace(manifest=None)
    assert prov.data_provenance(dm) == ({"manifest_hash": "h", "data_config_hash": "c"} if present
                                        else {"manifest_hash": None, "data_config_hash": None})
