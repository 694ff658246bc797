"""The cluster path on one machine: a 2-job multirun through Hydra's submitit launcher in local mode.

``hydra/launcher=slurm_local`` is ``hydra/launcher=slurm`` less the cluster keys (both take their
shared settings from ``conf/hydra/launcher/_submitit_common.yaml``): each sweep point is pickled by
the launcher and run by submitit in a process of its own, as on a SLURM cluster, so a job that does
not pickle, or a launcher setting that does not resolve, fails here before it reaches a cluster.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
import yaml
from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra
from omegaconf import OmegaConf

from lit3d.runtime.build import build_datamodule
from lit3d.runtime.compose import CONF_DIR
from tests.helpers.paths import REPO

# completion at demo net sizes with tiny latents, one short epoch; data.seed fixed so that the jobs
# (seeds 1 and 2) share the dataset made once beforehand
TINY = ["experiment=completion_demo", "data.sizes={train:4,val:2,test_same:2,test_cross:2,test_unseen:2}",
        "data.batch_size=2", "data.seed=0", "data.prepare.progress=false", "task.nets.latent_dim=64", "task.nets.k=16",
        "task.nets.fixed_latent_dim=64", "task.prior_samples=2", "trainer.max_epochs=1",
        "trainer.log_every_n_steps=1", "callbacks.progress_bar=null"]
METRICS = ["test/same/iou", "test/cross/iou"]
CLUSTER_KEYS = {"partition", "qos", "comment", "constraint", "exclude", "gres", "cpus_per_gpu", "gpus_per_task",
                "mem_per_gpu", "mem_per_cpu", "account", "signal_delay_s", "max_num_timeout",
                "additional_parameters", "array_parallelism", "setup"}


def _launcher(name: str) -> dict:
    GlobalHydra.instance().clear()
    try:
        with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
            cfg = compose("train", overrides=[f"hydra/launcher={name}"], return_hydra_config=True)
        return OmegaConf.to_container(cfg.hydra.launcher, resolve=False)
    finally:
        GlobalHydra.instance().clear()


def test_slurm_and_local_share_everything_but_the_cluster_keys():
    slurm, local = _launcher("slurm"), _launcher("slurm_local")
    assert slurm["_target_"].endswith("SlurmLauncher") and local["_target_"].endswith("LocalLauncher")
    assert set(slurm) - set(local) <= CLUSTER_KEYS
    assert {k: v for k, v in slurm.items() if k in local and k != "_target_"} == \
           {k: v for k, v in local.items() if k != "_target_"}
    assert local["tasks_per_node"] == "${trainer.devices}" and local["timeout_min"] == 1440


@pytest.mark.slow  # about 15 s; the launcher is Hydra's plugin (make test-all runs it)
def test_two_job_multirun_through_submitit_local(tmp_path, compose_cfg):
    data = tmp_path / "data"
    build_datamodule(compose_cfg(TINY, data_dir=data).data).prepare_data()  # once, before the jobs
    sweep = tmp_path / "sweep"
    res = subprocess.run(
        [str(Path(sys.executable).parent / "lit3d-train"), "-m", "hydra/launcher=slurm_local", *TINY, "seed=1,2",
         f"paths.data_dir={data}", f"hydra.sweep.dir={sweep}",
         f"hydra.callbacks.collect.metrics=[{','.join(METRICS)}]"],  # the default collector's columns
        cwd=REPO, env={**os.environ, "OMP_NUM_THREADS": "1"},  # two jobs at once on a small CPU
        capture_output=True, text=True, timeout=600)
    job_logs = "\n".join(p.read_text()[-2000:] for p in sorted(sweep.glob(".submitit/*/*_log.*")))
    assert res.returncode == 0, res.stdout[-3000:] + res.stderr[-3000:] + job_logs

    # two jobs, each run by submitit in a process of its own, from its pickle
    folders = sorted(p for p in (sweep / ".submitit").iterdir() if p.is_dir() and any(p.glob("*_submitted.pkl")))
    assert len(folders) == 2
    for folder in folders:
        assert any(folder.glob("*_result.pkl"))
        assert "Job completed successfully" in "".join(p.read_text() for p in folder.glob("*_log.*"))

    table = (sweep / "sweep_results.md").read_text()
    for job, seed in ((0, 1), (1, 2)):
        run = sweep / str(job)
        assert f"seed={seed}" in yaml.safe_load((run / ".hydra" / "overrides.yaml").read_text())
        metrics = json.loads((run / "metrics.json").read_text())
        assert all(0.0 <= metrics[m] <= 1.0 for m in METRICS)
        assert (run / "checkpoints" / "last.ckpt").is_file()
        # sweep_results.md collects both jobs' metrics
        row = next(ln for ln in table.splitlines() if ln.startswith(f"| {job} | seed={seed} |"))
        assert row.split("|")[3].strip() == f"{metrics[METRICS[0]]:.3f}"
    assert "Mean ± sd over seeds" in table
