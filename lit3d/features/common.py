"""What the mesh table (:mod:`lit3d.features.table`) and the point-cloud table
(:mod:`lit3d.features.point_table`) share, imported by both (neither imports the other's internals):

- the configuration and result types: :class:`FeatureConfig` (and :func:`feature_config`, one
  from plain options), :class:`ShapeViews`,
  :class:`FeatureTable`, :func:`overall_score`, the cache key :func:`content_key`;
- the feature cache: :func:`cache_path`, :func:`read_cached_table`, :func:`write_cached_table`
  (JSON files ``<key>.json``, written atomically and sorted);
- the worker threads that measure whole views: :func:`view_workers`;
- the per-view image measures: :func:`crop_box`, :func:`pair_measures` (every measure of a
  batch of grey image pairs given as crops), :func:`view_crop`, :func:`chunked_measures` and
  :func:`view_measures` (every measure of every MatCap style of one view).

Exact shortcuts (same numbers as the full-canvas definitions): SSIM-family maps,
MSE/RMSE/PSNR/SRE and Canny are computed on the bounding box of the union of all
foreground masks plus a margin wider than every filter support; background
pixels far from the shape have SSIM exactly 1, zero error and no edges, and are
added back analytically. MS-SSIM and FSIM (global statistics) always use the
full canvas; FSIM runs on images averaged down by ``fsim_downsample``.
"""
from __future__ import annotations

import hashlib
import json
import warnings
from collections.abc import Callable, Iterator, Mapping
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from lit3d.metrics import image as im
from lit3d.render.colour_styles import COLOUR_STYLES
from lit3d.render.gbuffer import RenderConfig
from lit3d.render.styles import apply_styles, resolve_styles
from lit3d.utils.io import output_error, write_json

FEATURE_VERSION = 2
IMAGE_MEASURES = ("mask_ssim", "mask_ssim_window", "mask_ssim_negative", "mask_ssim_merge", "ssim",
                  "ms_ssim", "fsim", "mse", "rmse", "psnr", "canny", "sre")
MESH_MEASURES = ("chamfer", "hausdorff")
# measures of the RGB colour styles of coloured shapes (lit3d.metrics.image.colour_measures): CIEDE2000 inside
# the masks and piq's full-reference colour measures
COLOUR_MEASURES = ("ciede2000", "fsimc", "vif", "gmsd", "haarpsi", "mdsi", "vsi")
# the field's point-cloud metrics of two point clouds (lit3d.metrics.pointssim, lit3d.metrics.pcqm)
POINT_MEASURES = ("pointssim", "pcqm")
# the colour styles (of lit3d.render.colour_styles.COLOUR_STYLES) the unlearned score averages (the later
# ``matcap_*`` styles are features only, so the unlearned score keeps the figures published for it)
UNLEARNED_COLOUR_STYLES = ("albedo_rgb", "albedo_luma", "lit_rgb", "lit_luma")
CROP_MARGIN = 8  # > SSIM radius (5) + 1 and > Canny support (2 blur + 1 Sobel + 1 NMS) + 1


# --------------------------------------------------------------------------- configuration and result
@dataclass(frozen=True)
class FeatureConfig:
    """Everything that determines a feature table (its JSON is part of the cache key).

    Attributes:
        render: image size, view extent, shadings.
        styles: style names (default: all 30).
        measures: image measures to compute (default: all of :data:`IMAGE_MEASURES`).
        mesh_measures: include Chamfer/Hausdorff (and, for point clouds, D1/D2/Y-PSNR).
        colour_measures: measures of the RGB colour styles of coloured point clouds (subset of
            :data:`COLOUR_MEASURES`, ``fsimc`` being piq's chromatic FSIM; names ``<measure>/<style>/<shading>``).
        point_measures: the field's point-cloud metrics of two point clouds (subset of :data:`POINT_MEASURES`).
        n_samples: surface samples per mesh for the 3-D measures.
        fsim_downsample: FSIM image reduction factor (2: 256 px renders -> 128 px).
        chunk: styles per batched measure call (memory bound; 0 = all styles of a view at once).
        workers: CPU threads measuring views in parallel (0 = ``torch.get_num_threads()``).
    """

    render: RenderConfig = field(default_factory=RenderConfig)
    styles: tuple[str, ...] = ()
    measures: tuple[str, ...] = IMAGE_MEASURES
    mesh_measures: bool = True
    colour_measures: tuple[str, ...] = COLOUR_MEASURES
    point_measures: tuple[str, ...] = POINT_MEASURES
    n_samples: int = 20000
    fsim_downsample: int = 2
    chunk: int = 8
    workers: int = 0

    def resolved_styles(self) -> list[str]:
        """The style names (all registered styles when ``styles`` is empty)."""
        return resolve_styles(list(self.styles) if self.styles else None)

    def key_dict(self) -> dict:
        """The configuration as it enters the cache key (without ``chunk`` and ``workers``)."""
        d = asdict(self)
        d["render"] = self.render.as_dict()
        d["styles"] = self.resolved_styles()
        d["measures"] = list(self.measures)
        d["colour_measures"] = list(self.colour_measures)
        d["point_measures"] = list(self.point_measures)
        d.pop("chunk")  # neither changes the numbers
        d.pop("workers")
        d["version"] = FEATURE_VERSION
        return d

    @classmethod
    def rendered(cls, size: int, styles=None) -> FeatureConfig:
        """The feature table ``lit3d-score`` computes: ``size`` px renders in ``styles`` (names, a
        comma list; None, ``"all"`` or empty: every style), the other fields at their defaults."""
        return cls(render=RenderConfig(size=int(size)), styles=tuple(resolve_styles(styles or "all")))


def feature_config(options: Mapping[str, Any] | None = None) -> FeatureConfig:
    """:class:`FeatureConfig` from plain options, as stored in data configs and checkpoints
    (``data.feature_options``): ``size``, ``extent``, ``distance``, ``shadings``, ``styles``,
    ``measures``, ``mesh_measures``, ``n_samples``, ``fsim_downsample``, ``chunk``, ``workers``
    (missing -> the defaults; ``cache_dir`` is ignored). The one definition: the data's feature
    function and :meth:`lit3d.quality.predict.QualityPredictor.feature_config` both call it."""
    o = dict(options or {})
    render_kw = {k: o.pop(k) for k in ("size", "extent", "distance") if k in o}
    if "shadings" in o:
        render_kw["shadings"] = tuple(o.pop("shadings"))
    o.pop("cache_dir", None)
    for k in ("styles", "measures", "colour_measures", "point_measures"):
        if k in o and o[k] is not None:
            o[k] = tuple(o[k])
    return FeatureConfig(render=RenderConfig(**render_kw), **o)


@dataclass
class ShapeViews:
    """Rendered grey style images of one mesh (:func:`lit3d.features.table.render_views`).

    Attributes:
        images: ``{shading: (S, V, 1, H, W) float32}`` in ``[0, 1]``.
        masks: ``{shading: (V, 1, H, W) bool}``.
        normals: ``{shading: (V, 3, H, W) float32}`` view-space normals.
    """

    images: dict[str, torch.Tensor]
    masks: dict[str, torch.Tensor]
    normals: dict[str, torch.Tensor]


@dataclass
class FeatureTable:
    """Features of one pair: ``features`` maps name -> float (12-view means).

    ``per_view`` (only when freshly computed, not from cache) maps name ->
    ``(V,)`` numpy arrays; ``views`` keeps the rendered images if requested.
    """

    features: dict[str, float]
    key: str
    cached: bool = False
    per_view: dict[str, np.ndarray] | None = None
    views: tuple[ShapeViews, ShapeViews] | None = None

    def overall_score(self) -> float:
        """:func:`overall_score` of :attr:`features`."""
        return overall_score(self.features)


def overall_score(features: dict[str, float], measure: str = "mask_ssim") -> float:
    """The unlearned score: mean of ``measure/<style>/<shading>`` (default Mask-SSIM).

    Colour-less tables: the mean over every style and shading. Tables with colour styles
    (:data:`UNLEARNED_COLOUR_STYLES`: coloured point clouds or meshes): the
    mean over the colour styles only, i.e. over the images an observer of the coloured shape
    sees (its colours, silhouette and, in the lit styles, the shading of its geometry); the
    MatCap styles stay in the table as features for the learned score. (Until this revision the
    two blocks were weighted equally; README "Point clouds, colour and CPCD2" gives both
    figures and says which data the choice was made on.)
    """
    geo, col = [], []
    for k, v in features.items():
        if k.split("/")[0] == measure and k.count("/") == 2:
            style = k.split("/")[1]
            if style in UNLEARNED_COLOUR_STYLES:
                col.append(v)
            elif style not in COLOUR_STYLES:  # the MatCap styles; the other colour styles are features only
                geo.append(v)
    if not geo and not col:
        raise ValueError(f"no {measure}/* features in the table")
    return float(np.mean(col if col else geo))


def content_key(ref_hash: str, dist_hash: str, cfg: FeatureConfig) -> str:
    """Cache key: SHA-256 of both shape hashes and the feature configuration."""
    blob = json.dumps({"ref": ref_hash, "dist": dist_hash, "cfg": cfg.key_dict()}, sort_keys=True)
    return hashlib.sha256(blob.encode()).hexdigest()


# --------------------------------------------------------------------------- cache
def cache_path(cache_dir, key: str) -> Path | None:
    """``<cache_dir>/<key>.json`` (None without a cache folder)."""
    return Path(cache_dir) / f"{key}.json" if cache_dir is not None else None


def read_cached_table(path: Path | None, key: str) -> FeatureTable | None:
    """The table cached at ``path`` under ``key`` (``cached=True``), or None: no path, absent,
    unreadable or written under another key (then it is recomputed and overwritten)."""
    if path is None or not path.is_file():
        return None
    try:
        data = json.loads(path.read_text())
        if data.get("key") == key:
            return FeatureTable({k: float(v) for k, v in data["features"].items()}, key, cached=True)
    except (OSError, ValueError, KeyError):
        pass
    return None


class CacheWarning(UserWarning):
    """The optional feature cache could not be written (read-only, full disk...): the table is
    returned all the same, uncached; the message names the cache folder and the problem."""


def write_cached_table(path: Path | None, key: str, cfg: FeatureConfig, features: dict[str, float]) -> None:
    """Write ``{"key", "config": cfg.key_dict(), "features"}`` to ``path`` (atomic, sorted JSON;
    nothing without a path). The cache is optional: a write that fails (OSError) leaves no file
    and warns (:class:`CacheWarning`) instead of raising."""
    if path is None:
        return
    try:
        write_json(path, {"key": key, "config": cfg.key_dict(), "features": features})
    except OSError as exc:
        warnings.warn(CacheWarning(f"feature cache not written: {output_error(path.parent, exc)}"), stacklevel=2)


# --------------------------------------------------------------------------- worker threads
class _Now:
    """The result of a call made at once, with a :class:`concurrent.futures.Future`'s ``result()``."""

    def __init__(self, fn, *args, **kwargs):
        self.value = fn(*args, **kwargs)

    def result(self):
        return self.value


def view_worker_count(workers: int, device=None) -> int:
    """How many threads :func:`view_workers` runs calls on (1: every call at once in the caller): ``workers``, or
    ``torch.get_num_threads()`` for 0, on CPU; 1 on other devices. Read it before entering :func:`view_workers`
    (which sets the caller's intra-op threads to 1)."""
    on_cpu = device is None or torch.device(device).type == "cpu"
    return (workers if workers > 0 else torch.get_num_threads()) if on_cpu else 1


@contextmanager
def view_workers(workers: int, device=None) -> Iterator[Callable[..., Any]]:
    """``submit(fn, *args)`` -> an object with ``result()``, for measuring whole views in parallel.

    On CPU (``device`` None or a CPU device): ``workers`` threads (0 = ``torch.get_num_threads()``
    on entry), each with one intra-op thread, and one intra-op thread in the caller too (also with
    one worker). Per-op OpenMP teams on small crops stall badly on a busy machine: measured on a
    loaded 2-core CPU, workers=1 with 2 intra-op threads took 18-88 s for the 256^2 table that
    takes about 5 s with one thread. Other devices, or one worker: every call runs at once in the
    caller. On exit the pool is drained and the caller's thread count restored.
    """
    on_cpu = device is None or torch.device(device).type == "cpu"
    n = view_worker_count(workers, device)
    prev = torch.get_num_threads()
    pool = None
    if on_cpu:
        torch.set_num_threads(1)
    try:
        if n > 1:
            pool = ThreadPoolExecutor(n, initializer=torch.set_num_threads, initargs=(1,))
        yield pool.submit if pool is not None else _Now
    finally:
        if pool is not None:
            pool.shutdown(wait=True)
        torch.set_num_threads(prev)


# --------------------------------------------------------------------------- per-view measures
def crop_box(masks: torch.Tensor, margin: int) -> tuple[int, int, int, int]:
    """(y0, y1, x0, x1) of the union of ``masks (N, 1, H, W)`` grown by ``margin`` (clipped)."""
    h, w = masks.shape[-2:]
    any_fg = masks.flatten(0, 1).any(0)
    if not bool(any_fg.any()):
        return 0, min(h, 1 + 2 * margin), 0, min(w, 1 + 2 * margin)
    rows = any_fg.any(1).nonzero().squeeze(1)
    cols = any_fg.any(0).nonzero().squeeze(1)
    return (max(int(rows[0]) - margin, 0), min(int(rows[-1]) + margin + 1, h),
            max(int(cols[0]) - margin, 0), min(int(cols[-1]) + margin + 1, w))


def pair_measures(a: torch.Tensor, b: torch.Tensor, mask_a: torch.Tensor, mask_b: torch.Tensor,
                  crop: tuple[int, int, int, int], measures=IMAGE_MEASURES,
                  fsim_downsample: int = 2) -> dict[str, torch.Tensor]:
    """Every image measure for a batch of grey image pairs given as crops of larger canvases.

    Args:
        a, b: ``(N, 1, h, w) float32`` in ``[0, 1]``: the window at ``(y0, x0)`` of
            ``H x W`` canvases that are 0 (black background) outside it.
        mask_a, mask_b: ``(N, 1, h, w)`` or ``(1, 1, h, w)`` (shared by the batch) bool
            foreground, inside the window; each mask
            must be at least :data:`CROP_MARGIN` pixels from a window side that is not a
            canvas side (the SSIM, error and Canny values are then exactly those of the
            full canvases).
        crop: ``(y0, x0, H, W)``.
        measures: subset of :data:`IMAGE_MEASURES`.
        fsim_downsample: FSIM resolution factor (see :func:`lit3d.metrics.image.fsim`,
            whose ``crop`` form is an approximation of the full-canvas FSIM).

    Returns:
        ``{measure: (N,) float32}``.
    """
    want = set(measures)
    out: dict[str, torch.Tensor] = {}
    y0, x0, hh, ww = (int(v) for v in crop)
    total = float(hh * ww)
    outside = total - float(a.shape[-1] * a.shape[-2])
    need_map = want & {"mask_ssim", "mask_ssim_window", "mask_ssim_negative", "mask_ssim_merge", "ssim", "ms_ssim"}
    cs0 = None
    if need_map:
        lum, cs = im.ssim_parts(a, b, 11, 1.5, 1.0, 0.01, 0.03, "symmetric")
        smap = lum.mul_(cs)
        ms = im.mask_ssim_all(a, b, mask_a, mask_b, smap=smap)
        ms["ssim"] = (smap.flatten(1).sum(1) + outside) / total
        cs0 = (cs.flatten(1).sum(1) + outside) / total
        out.update({k: v for k, v in ms.items() if k in want})
        del lum, cs, smap
    if "ms_ssim" in want:
        out["ms_ssim"] = im.ms_ssim(a, b, padding="symmetric", cs0=cs0, crop=crop)
    if "fsim" in want:
        out["fsim"] = im.fsim(a, b, downsample=fsim_downsample, crop=crop)
    if want & {"mse", "rmse", "psnr", "sre"}:
        err = ((a - b) ** 2).flatten(1).sum(1) / total
        mu2 = (a.flatten(1).sum(1) / total) ** 2
        vals = {"mse": err, "rmse": err.sqrt(),
                "psnr": (10.0 * torch.log10(1.0 / err.clamp_min(1e-30))).clamp(max=im.PSNR_MAX_DB),
                "sre": (10.0 * torch.log10(mu2.clamp_min(1e-30) / err.clamp_min(1e-30))).clamp(
                    -im.PSNR_MAX_DB, im.PSNR_MAX_DB)}
        out.update({k: v for k, v in vals.items() if k in want})
    if "canny" in want:
        e = im.canny_edges(torch.cat([a, b]))
        ea, eb = e.chunk(2)
        out["canny"] = (ea ^ eb).float().flatten(1).sum(1) / total
    return out


def view_crop(ga, gb, v: int) -> tuple[tuple[slice, ...], tuple[int, int, int, int]]:
    """``(sl, crop)`` for view ``v`` of two G-buffers: ``sl`` indexes ``(1, C, h, w)`` out of their
    ``(V, C, H, W)`` maps (the union of both masks + :data:`CROP_MARGIN`), ``crop`` is the
    ``(y0, x0, H, W)`` that :func:`pair_measures` takes."""
    hh, ww = ga.mask.shape[-2:]
    y0, y1, x0, x1 = crop_box(torch.cat([ga.mask[v:v + 1], gb.mask[v:v + 1]]), CROP_MARGIN)
    return (slice(v, v + 1), slice(None), slice(y0, y1), slice(x0, x1)), (y0, x0, hh, ww)


def chunked_measures(ia: torch.Tensor, ib: torch.Tensor, ma: torch.Tensor, mb: torch.Tensor,
                     crop: tuple[int, int, int, int],
                     cfg: FeatureConfig) -> Iterator[tuple[int, int, dict[str, torch.Tensor]]]:
    """:func:`pair_measures` of the style images ``ia, ib (S, 1, h, w)`` (masks ``(1, 1, h, w)``)
    ``cfg.chunk`` styles at a time (0: all at once): yields ``(i, j, {measure: (j - i,) float32
    cpu})`` for styles ``i:j``, in order."""
    n = ia.shape[0]
    step = cfg.chunk if cfg.chunk > 0 else n
    for i in range(0, n, step):
        j = min(i + step, n)
        res = pair_measures(ia[i:j], ib[i:j], ma, mb, crop, cfg.measures, cfg.fsim_downsample)
        yield i, j, {k: t.float().cpu() for k, t in res.items()}


def view_measures(ga, gb, v: int, names: list[str], cfg: FeatureConfig) -> dict[str, torch.Tensor]:
    """Every measure of every style for view ``v`` of two G-buffers: ``{measure: (S,) float32 cpu}``.

    The styles are shaded on the view's crop only (:func:`view_crop`).
    """
    sl, crop = view_crop(ga, gb, v)
    ma, mb = ga.mask[sl], gb.mask[sl]
    ia = apply_styles(ga.normals[sl], ma, names, grey=True)[:, 0]  # (S, 1, h, w)
    ib = apply_styles(gb.normals[sl], mb, names, grey=True)[:, 0]
    out: dict[str, list[torch.Tensor]] = {}
    for _, _, res in chunked_measures(ia, ib, ma, mb, crop, cfg):
        for k, t in res.items():
            out.setdefault(k, []).append(t)
    return {k: torch.cat(t) for k, t in out.items()}
