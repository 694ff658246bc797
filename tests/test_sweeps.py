"""Collecting a multirun: one row per job, and mean ± sd per setting over seeds."""
from __future__ import annotations

import json

import numpy as np
import yaml

from lit3d.sweeps import collect, over_seeds


def _job(root, name, overrides, metrics):
    d = root / name
    (d / ".hydra").mkdir(parents=True)
    (d / ".hydra" / "overrides.yaml").write_text(yaml.safe_dump(overrides))
    (d / ".hydra" / "hydra.yaml").write_text(yaml.safe_dump(
        {"hydra": {"sweeper": {"params": {"task.adversarial": "true,false", "seed": "0,1,2"}}}}))
    if metrics is not None:
        (d / "metrics.json").write_text(json.dumps(metrics))


def test_collect_groups_seeds_into_mean_and_sd(tmp_path):
    values = {("true", 0): 0.30, ("true", 1): 0.34, ("true", 2): 0.35, ("false", 0): 0.40, ("false", 1): 0.38}
    for n, ((adv, seed), v) in enumerate(values.items()):
        _job(tmp_path, str(n), ["experiment=completion_demo", f"task.adversarial={adv}", f"seed={seed}"],
             {"test/same/iou": v})
    _job(tmp_path, "5", ["experiment=completion_demo", "task.adversarial=false", "seed=2"], None)  # failed job
    text = collect(tmp_path, ["test/same/iou"], {"task.adversarial=true": 0.7})
    assert "no metrics.json" in text
    gan = np.array([0.30, 0.34, 0.35])
    assert f"| task.adversarial=true | 3 | {gan.mean():.3f} ± {gan.std(ddof=1):.3f} | 0.700 |" in text
    assert f"| task.adversarial=false | 2 | 0.390 ± {np.std([0.40, 0.38], ddof=1):.3f} | – |" in text
    assert (tmp_path / "sweep_results.md").read_text() == text


def test_no_seed_table_without_repeated_settings():
    assert over_seeds({"task.nets.k=50": {"m": 1.0}, "task.nets.k=100": {"m": 2.0}}, ["m"]) == {}


def test_seeds_given_on_the_command_line_are_grouped_too(tmp_path):
    """``-m ... +sweep=X seed=42,0,1``: seed is not a sweeper param of the sweep file but is swept."""
    (tmp_path / "multirun.yaml").write_text(yaml.safe_dump(
        {"hydra": {"overrides": {"task": ["experiment=completion_demo", "seed=42,0,1", "data.sizes={a: 1, b: 2}"]}}}))
    for n, (k, seed, v) in enumerate([(50, 42, 0.4), (50, 0, 0.5), (100, 42, 0.6), (100, 0, 0.8)]):
        d = tmp_path / str(n)
        (d / ".hydra").mkdir(parents=True)
        (d / ".hydra" / "overrides.yaml").write_text(yaml.safe_dump([f"task.nets.k={k}", f"seed={seed}"]))
        (d / ".hydra" / "hydra.yaml").write_text(yaml.safe_dump({"hydra": {"sweeper": {"params": {"task.nets.k": "50,100"}}}}))
        (d / "metrics.json").write_text(json.dumps({"m": v}))
    text = collect(tmp_path, ["m"])
    assert "| 0 | task.nets.k=50, seed=42 | 0.400 |" in text
    assert f"| task.nets.k=100 | 2 | 0.700 ± {np.std([0.6, 0.8], ddof=1):.3f} |" in text
