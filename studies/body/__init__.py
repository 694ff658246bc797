"""The body-fit studies: held-out Anny people and FAUST with the slower comparisons (``evaluate``: the
optimisation alone, multi-start), the body-fit rows of the canonical table (``body_fit_rows``), FAUST through
the completion net (``faust_chain``). The regressor itself trains as a task: ``lit3d-train experiment=body_regressor``."""
