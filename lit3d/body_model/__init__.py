"""The Anny parametric body model (:mod:`lit3d.body_model.bodies`: ``BodyModel``, the joint limits and
axes, the draws of subjects and poses): a shared room, so that the canonical task's Anny data source
(:mod:`datamodules.canonical.sources`) and the body fit (:mod:`lit3d.body_fit`, ``lit3d-reconstruct
--body``) use one model without the fit importing a DataModule or Lightning."""
