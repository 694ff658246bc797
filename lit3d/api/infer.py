"""Run a loaded model (:func:`lit3d.load`) on numpy arrays or meshes.

    result = complete(depth, completer)                     # (H, W) metres -> mesh + occupancy
    probs = complete_grid(partial, completer)               # (r, r, r) bool -> (R, R, R) probabilities
    form = canonical_form(mesh_or_depth, mapper)            # -> canonical (S, S) depth and mask
    points = canonical_points(depth, mapper)                # (H, W) metres -> canonical-pose points
    out = score(reference, distorted)                       # the shipped model's MOS (coloured clouds) or Mask-SSIM

A wrong model for the function or an array of the wrong shape is one
:class:`lit3d.reconstruct.depth_io.InputError` line naming the argument and what it expected.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lit3d.cli.score import DEFAULT_SIZE
from lit3d.features.table import FeatureConfig, feature_table
from lit3d.geometry.normalise import normalise_vertices
from lit3d.quality.predict import QualityPredictor
from lit3d.quality.shipped import load_shipped
from lit3d.reconstruct.backproject import RECGAN_FOV_DEG, Intrinsics, backproject
from lit3d.reconstruct.canonical import CanonicalMapper
from lit3d.reconstruct.depth_io import InputError
from lit3d.reconstruct.pipeline import Completer, Options, Result, reconstruct
from lit3d.render.convert import to_mesh
from lit3d.render.depth import render_depth


def _model(model, kind: type, fn: str, task: str):
    if not isinstance(model, kind):
        raise InputError(f"{fn}: needs a {task} model (lit3d.load of a {task} checkpoint), "
                         f"got {type(model).__name__}")
    return model


def _array(x, shape: tuple, name: str, dtype=np.float32) -> np.ndarray:
    """``x`` as a finite ``dtype`` array of ``shape`` (None = any size on that axis)."""
    a = np.asarray(x)
    if a.ndim != len(shape) or any(s is not None and s != n for s, n in zip(shape, a.shape)):
        want = " x ".join("N" if s is None else str(s) for s in shape)
        raise InputError(f"{name}: expected an array of shape ({want}), got {a.shape}")
    a = a.astype(dtype, copy=False)
    if a.dtype.kind == "f" and not np.isfinite(a).all():
        raise InputError(f"{name}: {int((~np.isfinite(a)).sum())} non-finite values (NaN/inf)")
    return a


def complete(depth, model: Completer, intrinsics: Intrinsics | None = None,
             options: Options | None = None) -> Result:
    """Complete the object seen in one depth image (``lit3d-reconstruct``'s steps).

    Args:
        depth: ``(H, W)`` depth in metres along the optical axis, 0 = background.
        model: a completion model (:func:`lit3d.load`).
        intrinsics: the camera; default the 3D-RecGAN++ camera (49.124 degrees across both sides,
            centred) at this image size.
        options: how the object is cut from the image (mask, depth range, plane removal).

    Returns:
        :class:`lit3d.reconstruct.pipeline.Result`: ``mesh`` (trimesh, camera frame, metres),
        ``occupancy`` ``(R, R, R) bool``, ``probs`` ``(R, R, R) float32``, ``points``, ``timings``.
    """
    model = _model(model, Completer, "complete", "completion")
    depth = _array(depth, (None, None), "depth")
    h, w = depth.shape
    return reconstruct(depth, intrinsics or Intrinsics.from_fov(RECGAN_FOV_DEG, w, h), model, options,
                       label="depth")


def complete_grid(partial, model: Completer) -> np.ndarray:
    """The generator on one partial grid: ``(r, r, r)`` bool (in the training grids' frame, ``r`` =
    ``model.geometry.input_res``) -> ``(R, R, R) float32`` occupancy probabilities; occupied =
    above ``model.threshold``."""
    model = _model(model, Completer, "complete_grid", "completion")
    r = model.geometry.input_res
    return model.probabilities(_array(partial, (r, r, r), "partial", bool))


@dataclass
class CanonicalForm:
    """A canonical form and the image it came from, all ``(S, S)`` (``S`` = the net's image size):
    ``depth`` float32 in [0, 1] (nearer = larger, 0 = background) and ``mask`` bool of the canonical
    pose; ``input_depth`` / ``input_mask``: the posed image the net saw."""

    depth: np.ndarray
    mask: np.ndarray
    input_depth: np.ndarray
    input_mask: np.ndarray


def canonical_form(shape, model: CanonicalMapper, mask=None, azimuth: float = 0.0) -> CanonicalForm:
    """The canonical pose of a posed subject (the canonical task's net).

    Args:
        shape: a posed mesh (anything :func:`lit3d.render.convert.to_mesh` reads: a path, a trimesh),
            rendered as the training data are (centred, longest side 1, orthographic depth from
            ``azimuth`` degrees about the up axis); or an ``(S, S)`` depth image already in that
            convention (:mod:`lit3d.render.depth`: in [0.1, 1], nearer = larger, 0 = background).
        model: a canonical model (:func:`lit3d.load`).
        mask: ``(S, S)`` bool foreground of a depth image (default: ``depth > 0``).
    """
    model = _model(model, CanonicalMapper, "canonical_form", "canonical")
    s = model.image_size
    if isinstance(shape, np.ndarray) and shape.ndim == 2:
        depth = _array(shape, (s, s), "depth")
        mask = depth > 0 if mask is None else _array(mask, (s, s), "mask", bool)
    else:
        mesh = to_mesh(shape)
        depth, mask = render_depth(normalise_vertices(mesh.vertices)[0], np.asarray(mesh.faces), s, azimuth)
    canon_depth, canon_mask = model.predict(depth, mask)
    return CanonicalForm(canon_depth, canon_mask, depth, mask)


def canonical_points(depth, model: CanonicalMapper, intrinsics: Intrinsics | None = None) -> np.ndarray:
    """A camera depth image ``(H, W)`` in metres (0 = background) -> ``(M, 3) float64`` points of the
    subject's canonical pose in the camera frame, at the posed subject's place and size: what
    ``lit3d-reconstruct --canonical`` completes (:mod:`lit3d.reconstruct.canonical`)."""
    model = _model(model, CanonicalMapper, "canonical_points", "canonical")
    depth = _array(depth, (None, None), "depth")
    h, w = depth.shape
    intr = (intrinsics or Intrinsics.from_fov(RECGAN_FOV_DEG, w, h)).check(w, h, "depth")
    points = backproject(depth, intr)
    if len(points) < 10:
        raise InputError(f"depth: {len(points)} foreground pixels (need at least 10)")
    return model.map_points(points, "depth")[0]


def _feature_config(model: QualityPredictor | None, size: int | None, styles) -> FeatureConfig:
    if model is None or model.feature_options is None:
        return FeatureConfig.rendered(size or DEFAULT_SIZE, styles)
    if model.feature_fn:
        raise InputError(f"{model.path}: the model was trained on features of data.feature_fn={model.feature_fn}, "
                         "not the renderer's feature table")
    if size is not None or styles is not None:
        raise InputError(f"{model.path}: size/styles are the model's own (it was trained on "
                         f"{model.feature_options}); leave them out")
    return model.feature_config()


def score(reference, distorted, model: QualityPredictor | None = None, *, size: int | None = None,
          styles=None, cache_dir=None, device=None, unlearned: bool = False) -> dict:
    """Quality of ``distorted`` against ``reference`` (``lit3d-score``'s measure).

    Args:
        reference, distorted: meshes, point clouds, voxel or SDF grids (paths or in-memory objects:
            anything :func:`lit3d.features.table.feature_table` reads).
        model: a quality model (:func:`lit3d.load`) or None: the shipped quality model
            (:mod:`lit3d.quality.shipped`) where the pair has its features (two coloured point
            clouds at the default renders), else the unlearned score.
        size, styles: render size in pixels (default 256) and MatCap style names (a list or a
            comma-separated string, default all); a model renders as it was trained instead. Either
            one given without a model: the unlearned score.
        cache_dir: folder of cached feature tables (None: no cache).
        unlearned: the unlearned score even where the shipped model could score the pair.

    Returns:
        ``{"score", "mask_ssim", "features", "model"}``: without a model's prediction ``score`` =
        ``mask_ssim``, the mean Mask-SSIM over styles, shadings and the 12 views (1 = identical
        renders) and ``model`` None; with one, the model's prediction on its training data's scale
        (``model``: the checkpoint path or ``shipped <name>``), plus what the model's ``predict``
        returns (``description``, ``distortion``, ...; the names it uses as ``model_features``).
    """
    shipped = None
    if model is not None:
        _model(model, QualityPredictor, "score", "quality")
        if unlearned:
            raise InputError("score: unlearned=True asks for the unlearned score: give no model with it")
    elif not unlearned and size is None and styles is None:
        shipped = load_shipped()
    cfg = shipped.feature_config() if shipped is not None else _feature_config(model, size, styles)
    table = feature_table(reference, distorted, cfg, cache_dir=cache_dir, device=device)
    out = {"score": table.overall_score(), "mask_ssim": table.overall_score(), "features": dict(table.features),
           "model": None}
    if shipped is not None and shipped.missing(table.features):
        shipped = None  # not a coloured point-cloud pair: the unlearned score
    predictor = model if model is not None else shipped
    if predictor is not None:
        prediction = predictor.predict(table.features)
        prediction["model_features"] = prediction.pop("features")  # the selected names it used
        prediction["model"] = model.path if model is not None else f"shipped {shipped.name}"
        out.update(prediction)
    return out
