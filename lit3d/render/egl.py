"""Headless OpenGL (EGL) set-up shared by every pyrender user in lit3d.

pyrender picks its platform from ``PYOPENGL_PLATFORM`` at import time, so
:func:`import_pyrender` sets it to ``egl`` (unless the user chose one) before
the first import, and pyglet (which pyrender's viewer imports) to headless,
so no X11 library is needed. EGL works on CPU machines through Mesa (llvmpipe) and on
NVIDIA GPUs through the driver.
"""
from __future__ import annotations

import ctypes.util
import functools
import os

from lit3d.utils.errors import Lit3dError

EGL_PACKAGES = "libegl1 libgl1 libgl1-mesa-dri libegl-mesa0"


class RenderBackendError(Lit3dError, RuntimeError):
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
    if os.environ["PYOPENGL_PLATFORM"] == "egl":
        # pyrender imports its pyglet viewer; headless pyglet needs EGL only, not X11 (absent on GPU servers)
        import pyglet

        pyglet.options["headless"] = True
    import pyrender  # platform must be set first

    return pyrender


def _keep_display(renderer) -> None:
    """Stop ``renderer`` from terminating the process-wide EGL display when it is deleted.

    pyrender's EGL platform calls ``eglTerminate`` on ``eglGetDisplay(EGL_DEFAULT_DISPLAY)``
    when a renderer is deleted or garbage collected. That display is shared by every
    renderer of the process, so one deleted renderer invalidates all the others
    (``eglMakeCurrent`` then fails with ``EGL_BAD_DISPLAY``, error 12296). We destroy only
    the renderer's own context.
    """
    platform = getattr(renderer, "_platform", None)
    if platform is None or not hasattr(platform, "_egl_display"):
        return

    def delete_context_only():
        from OpenGL.EGL import eglDestroyContext

        if platform._egl_display is not None and platform._egl_context is not None:
            eglDestroyContext(platform._egl_display, platform._egl_context)
        platform._egl_context = None
        platform._egl_display = None

    platform.delete_context = delete_context_only


def new_offscreen_renderer(width: int, height: int):
    """A fresh ``pyrender.OffscreenRenderer`` that leaves the shared EGL display alone on deletion.

    Raises:
        RenderBackendError: when no EGL context can be created.
    """
    pyrender = import_pyrender()
    try:
        renderer = pyrender.OffscreenRenderer(viewport_width=width, viewport_height=height)
    except Exception as exc:  # pragma: no cover - depends on the machine
        raise RenderBackendError(
            f"could not create an EGL context ({exc}); on CPU install `{EGL_PACKAGES}`, "
            "on a GPU check the NVIDIA driver"
        ) from exc
    _keep_display(renderer)
    return renderer


@functools.cache
def offscreen_renderer(width: int, height: int):
    """A cached ``pyrender.OffscreenRenderer`` of the given size (one per size and process).

    Creating an EGL context costs tens of milliseconds, so callers that render
    many views share one renderer per image size. The cache never evicts: an
    evicted renderer would be garbage collected mid-session.
    """
    return new_offscreen_renderer(width, height)
