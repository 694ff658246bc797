"""Fit the Anny body model (:mod:`lit3d.body_model.bodies`) to one depth image of a person.

    depth_points.py  depth + intrinsics -> camera-frame foreground points, silhouette distance map
    model.py      differentiable Anny: phenotype, joint-limited bone rotations, global similarity
                  -> camera-frame vertices
    fit.py        the optimisation (point-to-surface, silhouette, priors) from the mean body
    results.py    what a fit gives: posed and rest-pose meshes, the canonical depth image (rendered
                  as the canonical task renders its targets), fit quality, the parameters as JSON
    regressor.py  a small CNN: depth image -> the fit's parameters, the fit's start (--body-init)
    poses.py      the pose mixes of the regressor's training people
    synthetic.py  the evaluation's camera, rendering and sensor noise (evaluation and training)

A shared room: plain PyTorch and NumPy, neither a DataModule nor Lightning, so that
``lit3d-reconstruct --body`` (:mod:`lit3d.reconstruct.body`) loads neither. The regressor is trained
and evaluated as a task, :mod:`lit3d.body` (``lit3d-train experiment=body_regressor``).
"""
