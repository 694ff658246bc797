"""The body regressor task: the CNN that starts the Anny body fit (:mod:`lit3d.body_fit.regressor`),
trained and evaluated on the platform (``lit3d-train experiment=body_regressor``, ``lit3d-eval``).

    module.py      the LightningModule: loss, optimiser, schedule, logging
    evaluator.py   after the test: the body fit from the regressor on held-out Anny people and FAUST
    fit_scores.py  the fit's measures (per-vertex errors, Chamfer, F-scores) and the held-out people
    report.py      their tables
    figures.py     the picture of held-out people and their fits

The fit itself, the body model and the regressor's network are shared rooms (:mod:`lit3d.body_fit`,
:mod:`lit3d.body_model`): ``lit3d-reconstruct --body`` uses them without Lightning. The data is
:mod:`datamodules.body`.
"""
