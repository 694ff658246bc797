"""lit3d-reconstruct's camera: :mod:`lit3d.sensing.camera` (pinhole intrinsics, back-projection,
projection; the conventions are described there), whose checks raise lit3d-reconstruct's
:class:`~lit3d.reconstruct.depth_io.InputError` here.

Camera frame (OpenCV / depth-sensor convention): ``x`` right, ``y`` down in the image, ``z`` forward,
metres; pixel ``(u, v)`` has its centre at ``(u, v)``. The default camera is 3D-RecGAN++'s (a field
of view of :data:`RECGAN_FOV_DEG` degrees across both image sides, centred).
"""
from __future__ import annotations

from typing import ClassVar

from lit3d.reconstruct.depth_io import InputError
from lit3d.sensing import camera
from lit3d.sensing.camera import backproject, project  # noqa: F401 (re-exported)
from lit3d.sensing.sensor import RECGAN_FOV_DEG  # noqa: F401 (re-exported: the camera the data was made with)


class Intrinsics(camera.Intrinsics):
    """:class:`lit3d.sensing.camera.Intrinsics` whose checks raise :class:`InputError`."""

    error: ClassVar[type[Exception]] = InputError
