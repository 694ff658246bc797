"""The root of lit3d's own errors.

Every problem lit3d reports to its user (a bad option or config value, a bad data or input file, an
output that cannot be written, a checkpoint that does not fit) is a :class:`Lit3dError`, so
``except Lit3dError`` catches exactly those and lets real bugs through. The classes below it keep
their older built-in bases (``ValueError`` mostly), so code that caught those still does:

    Lit3dError
    ├── UserError              lit3d.cli.common: a bad path or option, printed as one line
    ├── ConfigValueError       lit3d.runtime.config_checks: a config value of the wrong type or range
    ├── DataError              datamodules.cache: a bad data file or data setting
    │   ├── DataConfigError    datamodules.completion.plan
    │   └── MosDataError       datamodules.quality.mos
    ├── MeshReadError          datamodules.canonical.tosca
    ├── InputError             lit3d.reconstruct.depth_io: a depth image or mask lit3d-reconstruct cannot use
    ├── BodyFitError           lit3d.body_fit.errors: a depth image a body cannot be fitted to (too few points)
    ├── BodyCheckpointError    lit3d.body_fit.errors: a body regressor checkpoint that cannot be used
    ├── CameraError            lit3d.sensing.camera: intrinsics that cannot describe an image
    ├── ShapeError             lit3d.render.convert: a mesh, cloud or grid that cannot be rendered
    ├── OutputError            lit3d.utils.io: an output path that cannot be written
    │   └── LockBusy           lit3d.utils.locks
    ├── QualityCheckpointError lit3d.quality.predict
    ├── RenderBackendError     lit3d.render.egl: no headless OpenGL
    ├── MissingExtra           lit3d.utils.extras: a feature whose optional extra is not installed (an ImportError too)
    └── NonFiniteLossError     lit3d.callbacks.nonfinite: training diverged

Signals are not errors: ``lit3d.cli.about.Stopped`` stays a ``KeyboardInterrupt``.
"""
from __future__ import annotations


class Lit3dError(Exception):
    """A problem lit3d reports to its user; the message names the file, option or value and the problem."""
