"""A small quality DataModule on synthetic shapes for the quality task's tests."""
from __future__ import annotations

from datamodules.quality import QualityDataModule


def make_dm(tmp_path, **kw) -> QualityDataModule:
    args = dict(data_dir=str(tmp_path / "q"), seed=0,
                synth={"shapes": ["blob", "bumpy", "torus", "rock"], "n_levels": 2,
                       "distortions": ["noise", "taubin", "simplify", "quantize"], "subdivisions": 3},
                feature_tables={"fn": "test_quality_task.fake_features"})
    args.update(kw)
    return QualityDataModule(**args)
