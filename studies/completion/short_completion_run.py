"""The reduced completion demo of tests/completion/test_completion_training.py, with extra overrides.

    .venv/bin/python -m studies.completion.short_completion_run TAG [hydra overrides ...]

Seed 0, 160 training shapes, 6 reconstruction-only epochs; writes /tmp/lit3d_short/TAG and
prints the test IoU of the model and of the input-as-prediction baseline per split.
"""
from __future__ import annotations

import json
import sys
import time
from pathlib import Path

from hydra import compose, initialize_config_dir
from omegaconf import open_dict

from lit3d.runtime.compose import CONF_DIR
from lit3d.cli.train import train

SHORT = ["experiment=completion_demo", "seed=0", "logger=csv", "callbacks.progress_bar=null",
         "data.sizes={train:160,val:24,test_same:24,test_cross:24,test_unseen:24}",
         "data.batch_size=4", "trainer.max_epochs=6", "task.adversarial.start_epoch=6"]


def main(tag: str, overrides: list[str]) -> None:
    root = Path("/tmp/lit3d_short")
    with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
        cfg = compose(config_name="train", overrides=[*SHORT, *overrides])
    with open_dict(cfg):
        cfg.paths.output_dir, cfg.paths.data_dir, cfg.paths.log_dir = str(root / tag), str(root / "data"), str(root / "logs")
    start = time.time()
    train(cfg)
    m = json.loads((root / tag / "metrics.json").read_text())
    ious = {k: round(v, 3) for k, v in m.items() if k.count("/") == 2 and k.endswith(("iou", "iou_input"))}
    print(f"RESULT {tag} {overrides} {time.time() - start:.0f}s {ious}")


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2:])
