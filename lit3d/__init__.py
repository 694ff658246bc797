"""lit3d: 3D reconstruction from depth images (shape completion, shape quality, canonical forms).

    import lit3d
    lit3d.__version__                       # from the installed package's metadata
    model = lit3d.load("best.ckpt")         # any task's checkpoint; see lit3d.api and docs/api.md

``import lit3d`` imports neither torch nor Lightning: ``__version__`` and the API names below are
looked up on first use (module ``__getattr__``).
"""
from __future__ import annotations

# the names of lit3d.api (tests/api/test_api.py checks that they match its __all__)
API = (
    "RECGAN_FOV_DEG", "CanonicalForm", "InputError", "Intrinsics", "Options", "canonical_form",
    "canonical_points", "checkpoint_task", "complete", "complete_grid", "export", "load", "models", "score",
    "untrained_checkpoint",
)
__all__ = ["__version__", *API]


def __getattr__(name: str):
    if name == "__version__":
        from lit3d.utils.provenance import lit3d_version

        value = lit3d_version()
    elif name in API:
        from lit3d import api

        value = getattr(api, name)
    else:
        raise AttributeError(f"module 'lit3d' has no attribute {name!r}")
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})
