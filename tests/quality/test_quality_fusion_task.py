"""The quality fusion as a task (lit3d.quality.fusion_task): fitted by a Trainer on a datamodule's training
split, its document in the shipped format, its checkpoint; and lit3d-train remaking the shipped model."""
from __future__ import annotations

import json
import subprocess
import sys

import lightning.pytorch as pl
import numpy as np
import pytest
from torch.utils.data import DataLoader

from datamodules.quality.settings import FeatureSettings
from datamodules.quality.batches import QualityPairDataset
from lit3d.features.matrix import FeatureMatrix, TargetScaling
from lit3d.quality.fusion_task import MODEL_FILE, QualityFusionTask
from lit3d.quality.shipped import DEFAULT_MODEL, MODELS_DIR, load_model_file
from tests.helpers.paths import SHARED_DATA

PHIL = SHARED_DATA / "cpcd2_phil"


class Rated(pl.LightningDataModule):
    """Three groups of rated pairs whose opinion follows PCQM plus Y-PSNR; the last group is the test split."""

    def __init__(self, informative: bool = True):
        super().__init__()
        rng = np.random.default_rng(0)
        n = 36
        pcqm, y_psnr, junk = rng.random(n) * 0.05, 20 + 15 * rng.random(n), rng.random(n)
        quality = -pcqm / 0.05 + 0.5 * (y_psnr - 20) / 15
        target = (quality.max() - quality) / np.ptp(quality) if informative else rng.random(n)
        groups = np.repeat(["G", "V", "N", "T"], 9)
        self.matrix = FeatureMatrix(np.stack([pcqm, y_psnr, junk], 1), ["pcqm", "y_psnr", "d1_psnr"], groups,
                                    target, [f"g/{i}" for i in range(n)], "toy")
        self.name, self.scaling = "toy", TargetScaling(1.0, 5.0, True, "MOS")
        self.hparams.update({"root": None})
        self.feature_settings = FeatureSettings(options={"size": 64, "cache_dir": "/tmp/x"})
        train = ~np.isin(groups, ["T"])
        self.splits = {"train": self.matrix.rows(train), "val": self.matrix.rows(~train),
                       "test": self.matrix.rows(~train)}

    feature_names = property(lambda self: self.matrix.names)
    shape_names = property(lambda self: self.matrix.shape_names)

    def split(self, name):
        return self.splits[name]

    def _loader(self, name):
        return DataLoader(QualityPairDataset(self.splits[name], self.shape_names), batch_size=4)

    def train_dataloader(self):
        return self._loader("train")

    def val_dataloader(self):
        return self._loader("val")

    def test_dataloader(self):
        return self._loader("test")


def trainer(tmp_path) -> pl.Trainer:
    return pl.Trainer(max_epochs=1, logger=False, enable_checkpointing=False, enable_progress_bar=False,
                      default_root_dir=tmp_path, enable_model_summary=False)


def test_the_task_fits_in_closed_form_and_writes_a_model_lit3d_score_can_read(tmp_path):
    task, dm = QualityFusionTask(model_name="toy-fusion", bootstrap=200), Rated()
    t = trainer(tmp_path)
    t.fit(task, datamodule=dm)
    doc = json.loads((tmp_path / MODEL_FILE).read_text())
    assert doc["name"] == "toy-fusion" and doc["feature_options"] == {"size": 64}  # the cache dir is no option
    assert set(doc["inner_scores"]) >= {"ridge:points", "anchored:pcqm+points"} and doc["chosen"] in doc["inner_scores"]
    r, lo, hi = doc["cross_validated"]["cross_validated (nested leave-one-group-out)"]["srocc_all"]
    assert r > 0.9 and lo <= r <= hi and t.callback_metrics["cv/srocc"] == pytest.approx(r)
    model = load_model_file(tmp_path / MODEL_FILE)
    test = dm.split("test")
    pred = [model.predict(dict(zip(test.names, row)))["score"] for row in test.X]
    assert np.corrcoef(pred, 1 - test.target)[0, 1] > 0.9  # MOS (higher = better) against quality
    metrics = t.test(task, datamodule=dm, verbose=False)[0]
    assert metrics["test/spearman"] > 0.9


def test_a_broken_target_is_not_learned_and_the_checkpoint_holds_the_model(tmp_path):
    task = QualityFusionTask(bootstrap=200)
    t = trainer(tmp_path)
    t.fit(task, datamodule=Rated(informative=False))
    assert t.callback_metrics["cv/srocc"] < 0.5
    t.save_checkpoint(tmp_path / "m.ckpt")
    again = QualityFusionTask.load_from_checkpoint(tmp_path / "m.ckpt")
    assert again.document == task.document and again.model.inputs == task.model.inputs


def test_fewer_than_three_groups_or_no_fusion_feature_is_one_clear_error():
    dm = Rated()
    two = dm.matrix.rows(np.isin(dm.matrix.shapes, ["G", "V"]))
    task = QualityFusionTask()
    with pytest.raises(ValueError, match="at least 3 training groups"):
        task.fit_fusion(two, dataset="toy", scaling=dm.scaling, feature_options={}, command="")
    with pytest.raises(ValueError, match="none of the fusion's features"):
        task.candidates(["mask_ssim/jade/flat"])


@pytest.mark.slow
@pytest.mark.skipif(not (PHIL / "mos.csv").is_file(), reason="../shared/data/cpcd2_phil not here")
def test_lit3d_train_remakes_the_shipped_quality_model(tmp_path):
    run = tmp_path / "run"
    out = subprocess.run([sys.executable, "-m", "lit3d.cli.train", "experiment=quality_cpcd2_fusion",
                          f"data.root={PHIL}", f"hydra.run.dir={run}", f"paths.data_dir={tmp_path / 'data'}",
                          "data.feature_tables.workers=2", "logger=[]", "~callbacks.progress_bar"],
                         capture_output=True, text=True, timeout=3000)
    assert out.returncode == 0, out.stderr[-3000:]
    made = json.loads((run / MODEL_FILE).read_text())
    shipped = json.loads((MODELS_DIR / f"{DEFAULT_MODEL}.json").read_text())
    assert made["chosen"] == shipped["chosen"]
    assert made["fusion"]["features"] == shipped["fusion"]["features"]
    np.testing.assert_allclose(made["fusion"]["corrections"], shipped["fusion"]["corrections"], atol=1e-9)
    np.testing.assert_allclose(made["fusion"]["opinion"]["params"], shipped["fusion"]["opinion"]["params"], rtol=1e-6)


def test_lit3d_score_model_option_refuses_a_missing_or_broken_file_in_one_line(tmp_path, capsys):
    from lit3d.cli.score import main

    shape = tmp_path / "a.xyz"
    shape.write_text("0 0 0\n1 0 0\n0 1 0\n0 0 1\n")
    bad = tmp_path / "bad.json"
    bad.write_text('{"name": "x"}')
    for extra, said in ((["--model", str(tmp_path / "nope.json")], "nope.json: no such quality model file"),
                        (["--model", str(bad)], "bad.json: not a readable shipped quality model"),
                        (["--model", str(bad), "--unlearned"], "without --model"),
                        (["--model", str(bad), "--ckpt", str(shape)], "give one")):
        assert main([str(shape), str(shape), *extra]) == 2, extra
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and said in err[0], (extra, err)
