"""Canonical-form data (task 3): posed depth -> canonical depth pairs from the built-in figures,
TOSCA or SHREC'14. The DataModule is :class:`~datamodules.canonical.datamodule.CanonicalDataModule`;
sources, depth images, splits and the dataset each have a module here."""
from datamodules.canonical.datamodule import *  # noqa: F403
from datamodules.canonical.datamodule import __all__  # noqa: F401
