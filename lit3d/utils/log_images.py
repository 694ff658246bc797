"""Images and meshes to whichever experiment loggers a run has (W&B, TensorBoard).

    log_image(trainer.loggers, "val/panels", pil_image, step)                   # -> loggers that took it
    log_mesh(trainer.loggers, "val/mesh/prediction", vertices, faces, step)

A logger is recognised by its class name or a base class's (``WandbLogger``, ``TensorBoardLogger``),
so this shared module imports neither Lightning nor W&B; other loggers (CSV) take no media and are
skipped. Meshes go to W&B as ``wandb.Object3D`` (an OBJ file) and to TensorBoard with ``add_mesh``.
"""
from __future__ import annotations

import io
from collections.abc import Iterable

import numpy as np

WANDB, TENSORBOARD = "wandb", "tensorboard"
_KINDS = {"WandbLogger": WANDB, "TensorBoardLogger": TENSORBOARD}


def logger_kind(logger) -> str | None:
    """``"wandb"``, ``"tensorboard"`` or None (a logger that takes no media, e.g. CSV)."""
    for cls in type(logger).__mro__:
        if cls.__name__ in _KINDS:
            return _KINDS[cls.__name__]
    return None


def media_loggers(loggers: Iterable | None) -> list:
    """The loggers of ``loggers`` that take images and meshes (W&B, TensorBoard), in order."""
    return [lg for lg in (loggers or ()) if logger_kind(lg) is not None]


def log_image(loggers: Iterable | None, key: str, image, step: int, caption: str | None = None) -> int:
    """Log an image (PIL, or an ``(H, W, 3)`` / ``(H, W)`` array: uint8, or float in [0, 1]) under
    ``key`` at ``step`` to every media logger; returns how many took it."""
    targets = media_loggers(loggers)
    for lg in targets:
        if logger_kind(lg) == WANDB:
            lg.log_image(key=key, images=[image], step=step, **({"caption": [caption]} if caption else {}))
        else:
            lg.experiment.add_image(key, hwc(image), global_step=step, dataformats="HWC")
    return len(targets)


def hwc(image) -> np.ndarray:
    """``(H, W, 3)`` array of a PIL image or of an ``(H, W)`` / ``(H, W, 3|4)`` array (dtype kept)."""
    array = np.asarray(image.convert("RGB")) if hasattr(image, "convert") else np.asarray(image)
    if array.ndim == 2:
        array = np.repeat(array[..., None], 3, axis=-1)
    if array.ndim != 3 or array.shape[-1] not in (3, 4):
        raise ValueError(f"expected an (H, W), (H, W, 3) or (H, W, 4) image, got shape {array.shape}")
    return array[..., :3]


def log_mesh(loggers: Iterable | None, key: str, vertices: np.ndarray, faces: np.ndarray, step: int) -> int:
    """Log a triangle mesh (``vertices (V, 3)`` float, ``faces (F, 3)`` int, 0-based) under ``key`` at
    ``step`` to every media logger; returns how many took it."""
    v = np.asarray(vertices, np.float32)
    f = np.asarray(faces, np.int64)
    if v.ndim != 2 or v.shape[1] != 3 or f.ndim != 2 or f.shape[1] != 3:
        raise ValueError(f"{key}: expected vertices (V, 3) and faces (F, 3), got {v.shape} and {f.shape}")
    targets = media_loggers(loggers)
    for lg in targets:
        if logger_kind(lg) == WANDB:
            import wandb

            obj = wandb.Object3D(io.StringIO(obj_text(v, f)), file_type="obj")
            lg.log_metrics({key: obj}, step=step)
        else:
            lg.experiment.add_mesh(key, vertices=v[None], faces=f[None], global_step=step)
    return len(targets)


def obj_text(vertices: np.ndarray, faces: np.ndarray) -> str:
    """Wavefront OBJ text of a triangle mesh (``faces`` 0-based, written 1-based)."""
    lines = [f"v {x:.5f} {y:.5f} {z:.5f}" for x, y, z in np.asarray(vertices, np.float64)]
    lines += [f"f {a} {b} {c}" for a, b, c in np.asarray(faces, np.int64) + 1]
    return "\n".join(lines) + "\n"
