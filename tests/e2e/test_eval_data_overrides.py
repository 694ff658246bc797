"""``lit3d-eval ckpt_path=X data.KEY=VALUE`` without ``data=NAME``: the overrides change the checkpoint's
own data config (before: Hydra refused them with its hint to add ``+data...``, as the eval config has
no data node then). A key the checkpoint's data config lacks and a value of the wrong type are one line."""
from __future__ import annotations

import subprocess
from pathlib import Path

import pytest
import yaml
from tests.helpers.runs import TINY_NETS
from tests.helpers.runs import BIN, REPO, child_env

from lit3d.api.checkpoints import untrained_checkpoint
from lit3d.runtime.errors import UserError
from lit3d.runtime.config_checks import ConfigValueError
from lit3d.cli.evaluate import data_overrides, with_data_overrides

SIZES = "data.sizes={train:2,val:2,test_same:2,test_cross:2,test_unseen:0}"


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("eval_data")
    return untrained_checkpoint("completion_demo", root / "c.ckpt", [*TINY_NETS, SIZES, "data.batch_size=2",
                                                                     "data.prepare.progress=false",
                                                                     f"paths.data_dir={root}/data"])


def _eval(args: list[str], timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run([str(BIN / "lit3d-eval"), *args], cwd=REPO, env=child_env(), capture_output=True, text=True,
                          timeout=timeout)


def test_data_keys_without_a_data_group_go_to_the_checkpoints_config():
    args = ["ckpt_path=x.ckpt", "data.num_workers=1", "+data.sizes.val=3", "evaluation.cv=false"]
    assert data_overrides(args) == ["ckpt_path=x.ckpt", "+data_overrides.num_workers=1", "+data_overrides.sizes.val=3",
                                    "evaluation.cv=false"]
    with_data = ["ckpt_path=x.ckpt", "data=recgan", "data.root=/r"]
    assert data_overrides(with_data) == with_data  # data=NAME: Hydra's own node takes them
    meta = {"num_workers": 4, "sizes": {"train": 2, "val": 1}, "kinds": ["a"]}
    assert with_data_overrides(meta, {"num_workers": 1, "sizes": {"val": 3}, "kinds": ["b"]}, "x.ckpt") == {
        "num_workers": 1, "sizes": {"train": 2, "val": 3}, "kinds": ["b"]}
    with pytest.raises(UserError, match=r"^data.sizes.tset: not a key of the checkpoint's data config \(x.ckpt\); "
                                        r"known: train, val$"):
        with_data_overrides(meta, {"sizes": {"tset": 1}}, "x.ckpt")
    with pytest.raises(ConfigValueError, match=r"^data.num_workers=-1: expected an integer >= 0$"):
        with_data_overrides(meta, {"num_workers": -1}, "x.ckpt")


def test_bad_data_overrides_are_one_line(checkpoint, tmp_path):
    for extra, line in ((["data.num_workers=-1"], "error: data.num_workers=-1: expected an integer >= 0"),
                        (["data.nope=3"], f"error: data.nope: not a key of the checkpoint's data config ({checkpoint}); "
                                          "known: ")):
        res = _eval([f"ckpt_path={checkpoint}", f"hydra.run.dir={tmp_path}/run", *extra])
        assert res.returncode == 2, res.stderr[-3000:]
        lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
        assert "Traceback" not in res.stderr and lines[-1].startswith(line), res.stderr[-3000:]
    assert not (tmp_path / "run" / "metrics.json").exists()


@pytest.mark.slow
def test_eval_applies_data_overrides_to_the_checkpoints_data(checkpoint, tmp_path):
    """A whole evaluation on the checkpoint's data with another data_dir and test size: the data is prepared
    there with the override, and config.yaml records the data config evaluated."""
    run, data = tmp_path / "run", tmp_path / "elsewhere"
    res = _eval([f"ckpt_path={checkpoint}", f"hydra.run.dir={run}", f"data.data_dir={data}", "data.num_workers=0",
                 "data.sizes.test_cross=1", "n_figures=0"], timeout=600)
    assert res.returncode == 0, res.stderr[-3000:]
    cfg = yaml.safe_load((run / "config.yaml").read_text())["data"]
    assert cfg["data_dir"] == str(data) and cfg["num_workers"] == 0 and cfg["sizes"]["test_cross"] == 1
    assert cfg["sizes"]["test_same"] == 2  # the checkpoint's own value where nothing overrides it
    assert (data / "manifest.json").is_file() and (run / "metrics.json").is_file()
