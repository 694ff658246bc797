"""Task 2, shape quality (thesis ch. 4): the thesis MLP and its one trainer, Sequential Forward
Search, the leave-one-shape-out / cross-dataset protocol, the LightningModule and the evaluator.
The rendering features it learns from live below it, in :mod:`lit3d.features`."""
