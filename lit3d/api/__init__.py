"""lit3d's Python API: load a checkpoint of any task and run it on numpy arrays or meshes.

    import lit3d
    model = lit3d.load("best.ckpt")                     # the task is read from the checkpoint
    lit3d.models()                                      # the zoo: trained models in the package, lit3d.load(name)
    result = lit3d.complete(depth, model)               # completion: depth image -> mesh, occupancy
    form = lit3d.canonical_form(mesh, model)            # canonical: posed mesh or depth -> canonical depth
    out = lit3d.score("ref.obj", "dist.ply")            # quality: mean Mask-SSIM, or a model's score
    lit3d.export(model, "net.pt")                       # TorchScript of the completion / canonical net

``import lit3d`` stays cheap: these names are imported from here on first use (module-level
``__getattr__`` in ``lit3d/__init__.py``). Guide with runnable examples: ``docs/api.md``.
This package sits above ``lit3d.cli`` in the layer contract (``pyproject.toml``): it reuses the
runtime's task building (:func:`lit3d.runtime.build.build_task`) and nothing imports it back.
"""
from __future__ import annotations

from lit3d.api.checkpoints import checkpoint_task, load, models, untrained_checkpoint
from lit3d.api.export import export
from lit3d.api.infer import CanonicalForm, canonical_form, canonical_points, complete, complete_grid, score
from lit3d.reconstruct.backproject import RECGAN_FOV_DEG, Intrinsics
from lit3d.reconstruct.depth_io import InputError
from lit3d.reconstruct.pipeline import Options

__all__ = [
    "RECGAN_FOV_DEG", "CanonicalForm", "InputError", "Intrinsics", "Options", "canonical_form",
    "canonical_points", "checkpoint_task", "complete", "complete_grid", "export", "load", "models", "score",
    "untrained_checkpoint",
]
