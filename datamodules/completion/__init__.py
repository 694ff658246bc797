"""Shape-completion data (task 1): procedural depth voxels, the 3D-RecGAN++ release or real CAD
models, in one packed-bit cache. The DataModule is
:class:`~datamodules.completion.datamodule.CompletionDataModule` (``datamodules.completion.CompletionDataModule``
is the ``_target_`` of the data configs); the item plan, each source's preparation, the cache, the
shape generators and the readers each have a module here."""
from datamodules.completion.datamodule import (  # noqa: F401
    DATA_SOURCES,
    DEFAULT_SIZES,
    CompletionDataModule,
    DataConfigError,
)
