"""Run a loaded model (:func:`lit3d.load`) on numpy arrays or meshes.

    result = complete(depth, completer)                     # (H, W) metres -> mesh + occupancy
    probs = complete_grid(partial, completer)               # (r, r, r) bool -> (R, R, R) probabilities
    form = canonical_form(mesh_or_depth, mapper)            # -> canonical (S, S) depth and mask
    points = canonical_points(depth, mapper)                # (H, W) metres -> canonical-pose points
    out = score(reference, distorted)                       # the shipped model's MOS (coloured clouds) or Mask-SSIM

Every argument is checked at the door: a wrong model for the function, an array of the wrong shape
or type, a tuple where :class:`Intrinsics` belongs, a dict where :class:`Options` belongs, a size out
of range is one :class:`lit3d.reconstruct.depth_io.InputError` line naming the argument and what it
expected. Camera depth follows ``lit3d-reconstruct``'s one rule for files
(:func:`lit3d.reconstruct.depth_io.depth_from_array`): an integer array is depth units of
``depth_scale`` metres (millimetres by default; the type's maximum, 65535 for uint16, is "no
reading"), a float array is metres, a bool array is refused; NaN/inf, negative depth and an image of
nothing but background are refused, depth of ``1e4`` m or more is background, as in the CLI.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lit3d.features import SCORE_SIZE
from lit3d.features.table import FeatureConfig, feature_table
from lit3d.geometry.normalise import normalise_vertices
from lit3d.quality.predict import QualityPredictor
from lit3d.quality.shipped import load_shipped
from lit3d.reconstruct.backproject import RECGAN_FOV_DEG, Intrinsics, backproject
from lit3d.reconstruct.canonical import CanonicalMapper
from lit3d.reconstruct.depth_io import InputError, depth_from_array
from lit3d.reconstruct.pipeline import Completer, Options, Result, reconstruct
from lit3d.render.convert import to_mesh
from lit3d.render.depth import render_depth
from lit3d.sensing.camera import Intrinsics as SharedIntrinsics


def _model(model, kind: type, fn: str, task: str):
    if not isinstance(model, kind):
        raise InputError(f"{fn}: needs a {task} model (lit3d.load of a {task} checkpoint), "
                         f"got {type(model).__name__}")
    return model


def _array(x, shape: tuple, name: str, dtype=np.float32) -> np.ndarray:
    """``x`` as a finite ``dtype`` array (None: its own numeric type) of ``shape`` (None = any size on that axis)."""
    a = _numeric(x, name)
    if a.ndim != len(shape) or any(s is not None and s != n for s, n in zip(shape, a.shape)):
        want = " x ".join("N" if s is None else str(s) for s in shape)
        raise InputError(f"{name}: expected an array of shape ({want}), got {a.shape}")
    a = a if dtype is None else a.astype(dtype, copy=False)
    if a.dtype.kind == "f" and not np.isfinite(a).all():
        raise InputError(f"{name}: {int((~np.isfinite(a)).sum())} non-finite values (NaN/inf)")
    return a


def _numeric(x, name: str) -> np.ndarray:
    """``x`` as a numeric (bool, integer or float) numpy array; anything else is one line."""
    try:
        a = np.asarray(x)
    except Exception as exc:  # ragged lists and the like
        raise InputError(f"{name}: not an array ({type(exc).__name__})") from None
    if a.dtype.kind not in "biuf":
        raise InputError(f"{name}: expected a numeric array, got {type(x).__name__} of dtype {a.dtype}")
    return a


def _camera_depth(x, name: str, depth_scale: float) -> np.ndarray:
    """An ``(H, W)`` camera depth image in metres by the rule of the module doc."""
    a = _numeric(x, name)
    if a.ndim != 2:
        raise InputError(f"{name}: expected an array of shape (N x N), got {a.shape}")
    return depth_from_array(a, name, depth_scale)[0]


def _intrinsics(intrinsics, w: int, h: int) -> Intrinsics:
    if intrinsics is None:
        return Intrinsics.from_fov(RECGAN_FOV_DEG, w, h)
    if not isinstance(intrinsics, SharedIntrinsics):  # lit3d.Intrinsics or any camera built on the shared one
        raise InputError(f"intrinsics: expected lit3d.Intrinsics(fx, fy, cx, cy) in pixels (or None: the "
                         f"3D-RecGAN++ camera), got {type(intrinsics).__name__}")
    if not isinstance(intrinsics, Intrinsics):
        intrinsics = Intrinsics(intrinsics.fx, intrinsics.fy, intrinsics.cx, intrinsics.cy)
    return intrinsics.check(w, h, "intrinsics")


def _options(options, shape: tuple[int, int]) -> Options:
    """``options`` checked: an :class:`Options`, its mask ``(H, W)`` bool or 0/1, near/far numbers."""
    if options is None:
        return Options()
    if not isinstance(options, Options):
        raise InputError(f"options: expected lit3d.Options(mask=..., near=..., far=...), got {type(options).__name__}")
    for key in ("near", "far"):
        v = getattr(options, key)
        if v is not None and (isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v) or v < 0):
            raise InputError(f"options.{key}={v!r}: expected metres >= 0, or None")
    if options.near is not None and options.far is not None and options.near >= options.far:
        raise InputError(f"options.near={options.near} >= options.far={options.far}: empty depth range")
    if options.mask is None:
        return options
    mask = _binary(options.mask, shape, "options.mask")
    if not mask.any():
        raise InputError("options.mask: empty (no True pixel)")
    return Options(**{**vars(options), "mask": mask})


def _binary(x, shape: tuple, name: str) -> np.ndarray:
    """A bool array of ``shape``: bool, or integer/float holding only 0 and 1; other values refused."""
    a = _array(x, shape, name, dtype=None)
    if a.dtype != np.bool_ and not np.isin(a, (0, 1)).all():
        bad = a[~np.isin(a, (0, 1))].ravel()[0]
        raise InputError(f"{name}: {a.dtype} values other than 0 and 1 (e.g. {bad:g}); expected a 0/1 (bool) grid: "
                         "threshold it yourself (x > t)")
    return a.astype(bool)


def complete(depth, model: Completer, intrinsics: Intrinsics | None = None,
             options: Options | None = None, depth_scale: float = 0.001) -> Result:
    """Complete the object seen in one depth image (``lit3d-reconstruct``'s steps).

    Args:
        depth: ``(H, W)`` depth along the optical axis, 0 = background: float metres, or integer
            units of ``depth_scale`` metres (millimetres by default, as ``lit3d-reconstruct`` reads
            integer files); a bool array is refused (module doc).
        model: a completion model (:func:`lit3d.load`).
        intrinsics: the camera (:class:`Intrinsics`); default the 3D-RecGAN++ camera (49.124 degrees
            across both sides, centred) at this image size.
        options: how the object is cut from the image (:class:`Options`: mask ``(H, W)`` bool or 0/1,
            depth range, plane removal).
        depth_scale: metres per unit of integer depth.

    Returns:
        :class:`lit3d.reconstruct.pipeline.Result`: ``mesh`` (trimesh, camera frame, metres),
        ``occupancy`` ``(R, R, R) bool``, ``probs`` ``(R, R, R) float32``, ``points``, ``timings``.
    """
    model = _model(model, Completer, "complete", "completion")
    depth = _camera_depth(depth, "depth", depth_scale)
    h, w = depth.shape
    return reconstruct(depth, _intrinsics(intrinsics, w, h), model, _options(options, (h, w)), label="depth")


def complete_grid(partial, model: Completer) -> np.ndarray:
    """The generator on one partial grid: ``(r, r, r)`` bool (in the training grids' frame, ``r`` =
    ``model.geometry.input_res``) -> ``(R, R, R) float32`` occupancy probabilities; occupied =
    above ``model.threshold``. An integer or float grid is taken when it holds only 0 and 1; one
    with other values (probabilities, NaN) is refused, not thresholded: threshold it yourself."""
    model = _model(model, Completer, "complete_grid", "completion")
    r = model.geometry.input_res
    return model.probabilities(_binary(partial, (r, r, r), "partial"))


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
        mask: ``(S, S)`` bool (or 0/1) foreground of a depth image (default: ``depth > 0``).

    A depth image must be float, finite, in [0, 1] and not all 0 (an integer or bool array, values
    outside [0, 1], an all-background image and a mask without a pixel are refused).
    """
    model = _model(model, CanonicalMapper, "canonical_form", "canonical")
    s = model.image_size
    if isinstance(shape, np.ndarray) and shape.ndim == 2:
        depth = _canonical_depth(shape, s)
        mask = depth > 0 if mask is None else _binary(mask, (s, s), "mask")
        if not mask.any():
            raise InputError("mask: empty (no True pixel)")
    else:
        mesh = to_mesh(shape)
        depth, mask = render_depth(normalise_vertices(mesh.vertices)[0], np.asarray(mesh.faces), s, azimuth)
    canon_depth, canon_mask = model.predict(depth, mask)
    return CanonicalForm(canon_depth, canon_mask, depth, mask)


def _canonical_depth(x, s: int) -> np.ndarray:
    """An ``(S, S)`` depth image in the canonical net's convention (float in [0, 1], 0 = background)."""
    a = _numeric(x, "depth")
    if a.dtype.kind != "f":
        raise InputError(f"depth: a {a.dtype} array; expected float depth normalised to [0, 1] "
                         "(lit3d.render.depth; camera depth in metres: lit3d.canonical_points)")
    a = _array(a, (s, s), "depth")
    if a.min() < 0 or a.max() > 1:
        raise InputError(f"depth: values in [{float(a.min()):.4g}, {float(a.max()):.4g}]; expected normalised depth in "
                         "[0, 1] (camera depth in metres: lit3d.canonical_points)")
    if not (a > 0).any():
        raise InputError("depth: all background (every pixel is 0)")
    return a


def canonical_points(depth, model: CanonicalMapper, intrinsics: Intrinsics | None = None,
                     depth_scale: float = 0.001) -> np.ndarray:
    """A camera depth image ``(H, W)`` (0 = background; float metres or integer units of
    ``depth_scale`` metres, as :func:`complete`) -> ``(M, 3) float64`` points of the subject's
    canonical pose in the camera frame, at the posed subject's place and size: what
    ``lit3d-reconstruct --canonical`` completes (:mod:`lit3d.reconstruct.canonical`)."""
    model = _model(model, CanonicalMapper, "canonical_points", "canonical")
    depth = _camera_depth(depth, "depth", depth_scale)
    h, w = depth.shape
    points = backproject(depth, _intrinsics(intrinsics, w, h))
    if len(points) < 10:
        raise InputError(f"depth: {len(points)} foreground pixels (need at least 10)")
    return model.map_points(points, "depth")[0]


def _feature_config(model: QualityPredictor | None, size: int | None, styles) -> FeatureConfig:
    if model is None or model.feature_options is None:
        return FeatureConfig.rendered(size or SCORE_SIZE, styles)
    if model.feature_fn:
        raise InputError(f"{model.path}: the model was trained on features of data.feature_tables.fn={model.feature_fn}, "
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
        size, styles: render size in pixels (16..4096, default 256; others refused) and MatCap style names (a list or a
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
    if size is not None and (isinstance(size, bool) or not isinstance(size, (int, np.integer))
                             or not 16 <= size <= 4096):
        raise InputError(f"size={size!r}: expected 16..4096 pixels (lit3d-score --size), or None")
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
