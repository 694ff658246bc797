"""The body regressor's data: Anny people drawn and rendered on the fly (:class:`BodyDataModule`)."""
from datamodules.body.datamodule import BodyDataModule

__all__ = ["BodyDataModule"]
