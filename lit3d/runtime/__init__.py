"""The runtime below the console scripts and the Python API: config composition (:mod:`.compose`),
the config rules (:mod:`.config_checks`), task and DataModule building (:mod:`.build`), checkpoint reading
(:mod:`.checkpoints`), the task registry (:mod:`.registry`) and the user-error type (:mod:`.errors`).

``lit3d.cli`` (the console scripts) and ``lit3d.api`` (the Python API) both import this package; it
imports neither.
"""
