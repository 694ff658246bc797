"""Every training run keeps a CSV log and draws curves.png from it, whatever logger= says; the
TensorBoard logger gets the scalars and the validation panels (tiny canonical runs)."""
from __future__ import annotations

from pathlib import Path

import pytest
from PIL import Image

from lit3d.cli.train import train
from lit3d.utils.curves import PANEL_W, panels, read_csv_logs

pytestmark = pytest.mark.usefixtures("one_torch_thread")

TINY = ["experiment=canonical_tiny", "debug=limit", "test_after_fit=false", "callbacks.progress_bar=null",
        "evaluation.retrieval=null"]


@pytest.fixture(scope="module")
def data_dir(tmp_path_factory):
    """One tiny synthetic canonical dataset shared by the runs of this module."""
    return tmp_path_factory.mktemp("canonical_data")


def test_tensorboard_run_draws_curves_and_logs_panels(compose_cfg, data_dir):
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    cfg = compose_cfg([*TINY, "logger=tensorboard", "trainer.max_epochs=2"], data_dir=data_dir)
    train(cfg)
    run = Path(cfg.paths.output_dir)
    img = Image.open(run / "curves.png")
    assert img.width >= 3 * PANEL_W >= 3 * 256 and (run / "metrics.json").is_file()
    names = [name for name, _ in panels(read_csv_logs(sorted((run / "csv").glob("version_*/metrics.csv"))))]
    assert "val/depth_mse" in names and "train/loss" in names
    steps, _ = read_csv_logs(sorted((run / "csv").glob("version_*/metrics.csv")))["val/depth_mse"]
    assert len(steps) == 2  # one validation per epoch
    events = EventAccumulator(str(run / "tensorboard" / "version_0"), size_guidance={"images": 0})
    events.Reload()
    assert "val/panels" in events.Tags()["images"] and "val/depth_mse" in events.Tags()["scalars"]


def test_logger_none_still_keeps_the_csv_log_and_curves(compose_cfg, data_dir):
    cfg = compose_cfg([*TINY, "logger=none", "trainer.max_epochs=1"], data_dir=data_dir)
    train(cfg)
    run = Path(cfg.paths.output_dir)
    assert (run / "csv" / "version_0" / "metrics.csv").is_file() and (run / "curves.png").is_file()
    assert not (run / "tensorboard").exists() and not (run / "wandb").exists()
