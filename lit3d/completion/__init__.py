"""Task 1, shape completion (thesis ch. 3, 3DCascade-GAN): nets, losses, the LightningModule
(:mod:`.module`), and the evaluator that writes results.md and figures (:mod:`.report`)."""
