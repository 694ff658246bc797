"""Headless OpenGL (EGL) set-up shared by every pyrender user in lit3d.

pyrender picks its platform from ``PYOPENGL_PLATFORM`` at import time, so
:func:`import_pyrender` sets it to ``egl`` (unless the user chose one) before
the first import. EGL works on CPU machines through Mesa (llvmpipe) and on
NVIDIA GPUs through the driver.
"""
from __future__ import annotations

import ctypes.util
import functools
import os

EGL_PACKAGES = "libegl1 libgl1 libgl1-mesa-dri libegl-mesa0"


class RenderBackendError(RuntimeError):
    """Raised when no headless OpenGL context can be created."""


def egl_available() -> bool:
    """True when the EGL loader library can be found on this machine."""
    return ctypes.util.find_library("EGL") is not None


@functools.lru_cache(maxsize=1)
def import_pyrender():
    """Import pyrender on the EGL platform and return the module.

    Raises:
        RenderBackendError: with the Debian packages to install when the EGL
            libraries are missing.
    """
    os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
    if os.environ["PYOPENGL_PLATFORM"] == "egl" and not egl_available():
        raise RenderBackendError(
            f"EGL library not found: install it with `apt-get install {EGL_PACKAGES}`"
        )
    import pyrender  # noqa: PLC0415  (platform must be set first)

    return pyrender


@functools.lru_cache(maxsize=8)
def offscreen_renderer(width: int, height: int):
    """A cached ``pyrender.OffscreenRenderer`` of the given size (one per process).

    Creating an EGL context costs tens of milliseconds, so callers that render
    many views share one renderer per image size.
    """
    pyrender = import_pyrender()
    try:
        return pyrender.OffscreenRenderer(viewport_width=width, viewport_height=height)
    except Exception as exc:  # pragma: no cover - depends on the machine
        raise RenderBackendError(
            f"could not create an EGL context ({exc}); on CPU install `{EGL_PACKAGES}`, "
            "on a GPU check the NVIDIA driver"
        ) from exc
