"""Research studies beside the package: each folder holds a study's programs, its README (the question, the
current answer, the commands) and its LOG (the dated rounds). Run from the repository root, e.g.
``python -m studies.quality.cpcd2_study --root DATA``. ``lit3d`` and ``datamodules`` never import this package."""
