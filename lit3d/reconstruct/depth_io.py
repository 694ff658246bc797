"""Depth and mask image readers: every problem is one :class:`InputError` line naming the file.

Formats (``read_depth``), all returned as ``(H, W) float32`` metres, 0 = background:

- ``.png`` / ``.tif``: 16-bit single channel, integer depth units times ``depth_scale``
  metres (default 0.001: millimetres, as Kinect/RealSense write them); 0 = no reading;
- ``.npy`` / ``.npz``: a 2-D array (an ``.npz`` holds one array, or a key named ``depth``):
  float = metres, integer = depth units times ``depth_scale`` metres, as the images; 0 = background;
- ``.exr``: a float depth channel in metres, read with OpenCV's OpenEXR codec.

Integer depth equal to its type's maximum (65535 for 16 bits: a sensor's "no reading") and
pixels beyond ``1e4`` m (renderers' "infinitely far" background) count as background.
:func:`read_depth_info` also says which units were applied and how many pixels were taken as
"no reading" (written to the JSON of ``lit3d-reconstruct``, and printed as a note when non-zero).
A ``.npy``/``.npz`` is read by its content (an ``.npz`` archive named ``.npy`` is still an archive).
Refused with one line: a path that is not a regular file (a FIFO, a device: never read, it could
block), an image of several pages or frames (a multi-page TIFF: one depth image per file), an
image over Pillow's decompression-bomb limit. :func:`find_mask` pairs a mask folder's files with
the depth images by exact name stem.
"""
from __future__ import annotations

import os
import re
import zipfile
from pathlib import Path

import numpy as np

from lit3d.utils.errors import Lit3dError
from lit3d.utils.files import path_problem

DEPTH_SUFFIXES = (".png", ".tif", ".tiff", ".npy", ".npz", ".exr")
MASK_SUFFIXES = (".png", ".tif", ".tiff", ".npy", ".npz", ".bmp", ".jpg")
FAR_BACKGROUND = 1e4
MAX_MEDIAN_METRES = 100.0  # an object or a person this far is a unit mistake (float millimetres read as metres)


class InputError(Lit3dError, ValueError):
    """A bad input file or option: the message is one line naming the file and the problem."""


def regular_file(p: Path, what: str = "file") -> None:
    """Raise :class:`InputError` unless ``p`` is a regular file (or a link to one): missing, a
    broken link, a folder, a FIFO or device (not read: it could block) are each named as such, in
    the wording every command uses (:func:`lit3d.utils.files.path_problem`)."""
    problem = path_problem(p, what)
    if problem is None:
        return
    hint = "; give an image or array file" if problem.endswith(f"not a regular {what}") else ""
    raise InputError(f"{p}: {problem}{hint}")


def _image(path: Path) -> np.ndarray:
    """Pixels of an image file as an array (PIL; ``I;16`` stays uint16)."""
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(path) as im:
            pages = getattr(im, "n_frames", 1)
            if pages > 1:  # PIL would give page 1 alone
                what = "pages (a multi-page TIFF)" if im.format == "TIFF" else f"frames (an animated {im.format})"
                raise InputError(f"{path}: {pages} {what}; one depth image per file is read: save each page "
                                 "as its own file")
            im.load()
            return np.asarray(im)
    except Image.DecompressionBombError as exc:
        n = [f"{int(v):,}" for v in re.findall(r"\d+", str(exc))[:2]]  # "(N pixels) exceeds limit of M"
        size = f"of {n[0]} pixels, over the reader's limit of {n[1]}" if len(n) == 2 else "over the reader's limit"
        raise InputError(f"{path}: image {size} (Pillow's decompression-bomb guard); crop or downscale it") \
            from None
    except UnidentifiedImageError:
        raise InputError(f"{path}: not an image (unreadable as {path.suffix.lstrip('.').upper()})") from None
    except OSError as exc:
        raise InputError(f"{path}: not a readable image ({exc})") from None


def _array(path: Path) -> np.ndarray:
    """The array of a ``.npy``, or the one array (or key ``depth``) of an ``.npz``: by content, not suffix."""
    try:
        loaded = np.load(path, allow_pickle=False)
        if isinstance(loaded, np.ndarray):
            return loaded
        with loaded as z:
            keys = list(z.keys())
            if "depth" in keys:
                return z["depth"]
            if len(keys) != 1:
                raise InputError(f"{path}: expected one array or a key 'depth', found keys {keys}")
            return z[keys[0]]
    except InputError:
        raise
    except (ValueError, OSError, EOFError, zipfile.BadZipFile) as exc:
        raise InputError(f"{path}: not a readable numpy file ({type(exc).__name__})") from None


def _exr(path: Path) -> np.ndarray:
    os.environ.setdefault("OPENCV_IO_ENABLE_OPENEXR", "1")
    try:
        import cv2
    except ImportError:
        raise InputError(f"{path}: reading .exr needs OpenCV (pip install opencv-python-headless)") from None
    arr = cv2.imread(str(path), cv2.IMREAD_ANYDEPTH | cv2.IMREAD_ANYCOLOR)
    if arr is None:
        raise InputError(f"{path}: not a readable OpenEXR image (OpenCV could not decode it)")
    return arr[..., 0] if arr.ndim == 3 else arr  # depth renderers write it in every channel


def read_depth(path: str | os.PathLike, depth_scale: float = 0.001) -> np.ndarray:
    """Depth image -> ``(H, W) float32`` metres, 0 = background (see the module doc for formats).

    Raises:
        InputError: missing file, unknown format, not an image, wrong shape or type, NaN/inf,
            negative depth, all background.
    """
    return read_depth_info(path, depth_scale)[0]


def read_depth_info(path: str | os.PathLike, depth_scale: float = 0.001) -> tuple[np.ndarray, dict]:
    """:func:`read_depth` plus what was assumed: ``{"dtype", "units", "depth_scale_applied",
    "no_reading_pixels"}`` (``units``: ``"integer units x depth_scale"`` or ``"metres (float)"``)."""
    p = Path(path)
    regular_file(p)
    suffix = p.suffix.lower()
    if suffix not in DEPTH_SUFFIXES:
        raise InputError(f"{p}: unknown depth format '{p.suffix}' (expected {' '.join(DEPTH_SUFFIXES)})")
    if not depth_scale > 0 or not np.isfinite(depth_scale):
        raise InputError(f"--depth-scale {depth_scale}: expected a positive number of metres per unit")
    if suffix in (".png", ".tif", ".tiff"):
        raw = _image(p)
        if raw.ndim != 2:
            raise InputError(f"{p}: expected a single-channel 16-bit depth image, got {raw.ndim}-D pixels "
                             f"{tuple(raw.shape)} (a colour picture?)")
        if raw.dtype == np.uint8:
            raise InputError(f"{p}: 8-bit image: not a depth map (expected 16-bit depth units)")
    else:
        raw = np.asarray(_exr(p) if suffix == ".exr" else _array(p))
        while raw.ndim > 2 and raw.shape[0] == 1:  # (1, H, W): one image; a (1, 1) image stays 2-D
            raw = raw[0]
        while raw.ndim > 2 and raw.shape[-1] == 1:
            raw = raw[..., 0]
        if raw.ndim != 2 or raw.dtype.kind not in "fiu" or raw.dtype == np.bool_:
            raise InputError(f"{p}: expected a 2-D numeric depth array, got {raw.dtype} {tuple(raw.shape)}")
    return depth_from_array(raw, p, depth_scale)


def depth_from_array(raw: np.ndarray, label: str | os.PathLike,
                     depth_scale: float = 0.001) -> tuple[np.ndarray, dict]:
    """A 2-D depth array -> ``(H, W) float32`` metres by its type, the one rule of the files and the
    Python API: integer = units times ``depth_scale`` metres (millimetres by default), the type's
    maximum = "no reading" (background); float = metres; bool (a mask?) and other types refused.
    Then :func:`check_depth` (NaN/inf, negative, all background), and a median depth over
    :data:`MAX_MEDIAN_METRES` is refused as a unit mistake (float millimetres read as metres). Returns ``(depth, info)``, the
    ``info`` of :func:`read_depth_info`."""
    raw = np.asarray(raw)
    if raw.dtype == np.bool_ or raw.dtype.kind not in "fiu":
        what = "a bool array (a mask?)" if raw.dtype == np.bool_ else f"a {raw.dtype} array"
        raise InputError(f"{label}: {what} is not depth: expected float metres, or integer units of depth_scale "
                         f"metres ({depth_scale:g}: millimetres by default)")
    if not depth_scale > 0 or not np.isfinite(depth_scale):
        raise InputError(f"depth_scale {depth_scale}: expected a positive number of metres per unit")
    info = {"dtype": str(raw.dtype), "no_reading_pixels": 0}
    if raw.dtype.kind in "iu":
        no_reading = raw == np.iinfo(raw.dtype).max  # a sensor's "no reading" (65535 for 16 bits)
        info["no_reading_pixels"] = int(no_reading.sum())
        depth = np.where(no_reading, 0.0, raw.astype(np.float64) * depth_scale)
        info.update(units="integer units x depth_scale", depth_scale_applied=float(depth_scale))
    else:
        depth = raw.astype(np.float64)
        info.update(units="metres (float)", depth_scale_applied=None)
    if info["no_reading_pixels"] and not (depth > 0).any():
        raise InputError(f"{label}: all background (every depth pixel is 0 or {np.iinfo(raw.dtype).max}, "
                         "the sensor's 'no reading')")
    depth = check_depth(depth, label)
    median = float(np.median(depth[depth > 0]))
    if median > MAX_MEDIAN_METRES:  # before: float millimetres fitted a person 2.8 km away, with a "poor fit"
        read = ("float depth is read as metres" if raw.dtype.kind == "f"
                else f"integer depth times depth_scale {depth_scale:g} m")
        fix = ("float depth must be metres: divide by 1000, or save integer millimetres (a uint16 PNG or .npy)"
               if raw.dtype.kind == "f" else "check depth_scale (--depth-scale: metres per unit, 0.001 for millimetres)")
        raise InputError(f"{label}: {read}, and the depth's median is {median:.6g} m, more than {MAX_MEDIAN_METRES:g} m "
                         f"(millimetres?); {fix}")
    return depth, info


def check_depth(depth: np.ndarray, label: str | os.PathLike) -> np.ndarray:
    """Validate ``(H, W)`` depth in metres -> float32 copy with far background set to 0."""
    if min(depth.shape) < 2:
        raise InputError(f"{label}: depth image of shape {tuple(depth.shape)} is too small")
    bad = ~np.isfinite(depth)
    if bad.any():
        kind = "NaN" if np.isnan(depth).any() else "inf"
        raise InputError(f"{label}: {int(bad.sum())} depth pixels are {kind} (write 0 for background)")
    if (depth < 0).any():
        raise InputError(f"{label}: negative depth ({float(depth.min()):.4g}); expected metres >= 0, 0 = background")
    depth = np.where(depth >= FAR_BACKGROUND, 0.0, depth)
    if not (depth > 0).any():
        raise InputError(f"{label}: all background (every depth pixel is 0)")
    return depth.astype(np.float32)


def read_mask(path: str | os.PathLike, shape: tuple[int, int]) -> np.ndarray:
    """Object mask image or array -> ``(H, W) bool`` (non-zero = object); must match ``shape``."""
    p = Path(path)
    regular_file(p, "mask file")
    suffix = p.suffix.lower()
    arr = _array(p) if suffix in (".npy", ".npz") else _image(p)
    arr = np.asarray(arr)
    if arr.ndim == 3:  # colour or RGBA mask: any channel set
        arr = arr[..., :3].max(-1) if arr.shape[-1] in (3, 4) else arr.max(-1)
    if arr.shape != tuple(shape):
        raise InputError(f"{p}: mask is {tuple(arr.shape)}, the depth image is {tuple(shape)}")
    mask = arr > 0
    if not mask.any():
        raise InputError(f"{p}: mask is empty (no non-zero pixel)")
    return mask


def find_mask(mask: str | os.PathLike, depth_path: Path) -> Path:
    """The mask file of the depth image ``depth_path``: ``mask`` itself, or, for a folder, its file
    named exactly like the depth image's stem with a mask suffix (:data:`MASK_SUFFIXES`): no glob
    pattern (``scan[1].png`` pairs with ``scan[1].png``, never ``scan1.png``), no other suffix
    (``cow.json`` is not a mask). None there, or several (``cow.png``, ``cow.npy``): InputError."""
    m = Path(mask)
    if not m.is_dir():
        return m
    stem = depth_path.stem
    found = sorted(q for q in m.iterdir() if q.stem == stem and q.suffix.lower() in MASK_SUFFIXES)
    if not found:
        raise InputError(f"{depth_path}: no mask {m}/{stem}.<{'|'.join(s[1:] for s in MASK_SUFFIXES)}> "
                         "in the mask folder")
    if len(found) > 1:
        raise InputError(f"{depth_path}: {len(found)} masks for it in {m} ({', '.join(q.name for q in found)}); "
                         "keep one")
    return found[0]


def list_inputs(paths: list[str]) -> list[Path]:
    """Command-line inputs -> depth files: a folder gives its depth files (sorted, not recursive)."""
    out: list[Path] = []
    for s in paths:
        p = Path(s)
        if p.is_dir():
            found = sorted(q for q in p.iterdir() if q.is_file() and q.suffix.lower() in DEPTH_SUFFIXES)
            if not found:
                raise InputError(f"{p}: folder holds no depth files ({' '.join(DEPTH_SUFFIXES)})")
            out += found
        else:
            out.append(p)
    return out
