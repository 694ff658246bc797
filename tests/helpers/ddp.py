"""The runs that the DDP equivalence tests (CPU) and the GPU tests compare."""
from __future__ import annotations

COMMON = ["logger=none", "callbacks.progress_bar=null", "trainer.max_epochs=1", "+trainer.limit_train_batches=2",
          "+trainer.limit_val_batches=1", "test_after_fit=false", "seed=0"]


CASES = {
    "completion": ["experiment=completion_demo", "data.sizes={train:8,val:5,test_same:5,test_cross:3,test_unseen:5}",
                   "data.batch_size=2"],
    "canonical": ["experiment=canonical_tiny", "data.source.n_subjects=6", "data.source.n_poses=6", "data.image_size=32",
                  "task.net.image_size=32", "data.batch_size=3", "evaluation.mesh_baselines=[posed]",
                  "evaluation.retrieval.view_size=32"],
    "quality": ["experiment=quality_demo", "+data.feature_tables.fn=tests.helpers.quality.fake_features",
                "~data.feature_tables.options",
                "data.synth.subdivisions=2", "data.synth.shapes=[blob,bumpy,torus,rock,twist]", "evaluation.cv=false",
                "task.sfs.epochs=5",
                "task.sfs.max_features=2"],
}
