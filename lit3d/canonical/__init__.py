"""Task 3, canonical forms (thesis ch. 5): nets (LFE/MSFE), losses, the loss-phase callback,
the LightningModule (:mod:`.module`), the mesh baselines' wiring and the evaluator (:mod:`.report`)."""
