"""Shape-quality data (task 2): feature tables of (reference, distorted) mesh pairs with their
scores, from built-in procedural shapes or a MOS dataset. The DataModule is
:class:`~datamodules.quality.datamodule.QualityDataModule`; batching, feature extraction and the
preview each have a module here."""
from datamodules.quality.datamodule import (  # noqa: F401
    PROCEDURAL_SHAPES,
    SEVERITY_NAME,
    QualityDataModule,
    procedural_shape,
)
