"""Feature table of a (reference, distorted) mesh pair: measure x style x shading, 12-view means.

Pipeline per mesh: ``to_mesh`` -> normalise -> one G-buffer pass per view and
shading (:mod:`lit3d.render.gbuffer`) -> all styles as one batched MatCap
look-up (:mod:`lit3d.render.styles`). Then every image measure runs once over
the whole batch of ``shadings x styles x views`` grey image pairs (in chunks of
``chunk`` images to bound memory) and is averaged over the views.

Feature names are ``measure/style/shading`` (``mask_ssim_window/ceramic_lightbulb/flat``)
plus the 3-D features ``chamfer`` and ``hausdorff``. Images are grey (BT.601 luma
of the RGB MatCap) in ``[0, 1]`` on a black background.

Exact shortcuts (same numbers as the full-canvas definitions): SSIM-family maps,
MSE/RMSE/PSNR/SRE and Canny are computed on the bounding box of the union of all
foreground masks plus a margin wider than every filter support; background
pixels far from the shape have SSIM exactly 1, zero error and no edges, and are
added back analytically. MS-SSIM and FSIM (global statistics) always use the
full canvas; FSIM runs on images averaged down by ``fsim_downsample``.

Tables are cached on disk as JSON (atomic temp file + rename) keyed by the SHA-256
of both meshes' vertex/face arrays and the feature configuration.
"""
from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch

from lit3d.metrics import image as im
from lit3d.metrics.mesh import chamfer_hausdorff
from lit3d.render.convert import mesh_hash, to_mesh
from lit3d.render.gbuffer import RenderConfig, render_gbuffers
from lit3d.render.points import is_point_source
from lit3d.render.styles import apply_styles, resolve_styles

FEATURE_VERSION = 2
IMAGE_MEASURES = ("mask_ssim", "mask_ssim_window", "mask_ssim_negative", "mask_ssim_merge", "ssim",
                  "ms_ssim", "fsim", "mse", "rmse", "psnr", "canny", "sre")
MESH_MEASURES = ("chamfer", "hausdorff")
_CROP_MARGIN = 8  # > SSIM radius (5) + 1 and > Canny support (2 blur + 1 Sobel + 1 NMS) + 1


@dataclass(frozen=True)
class FeatureConfig:
    """Everything that determines a feature table (its JSON is part of the cache key).

    Attributes:
        render: image size, view extent, shadings.
        styles: style names (default: all 30).
        measures: image measures to compute (default: all of :data:`IMAGE_MEASURES`).
        mesh_measures: include Chamfer/Hausdorff.
        n_samples: surface samples per mesh for the 3-D measures.
        fsim_downsample: FSIM image reduction factor (2: 256 px renders -> 128 px).
        chunk: styles per batched measure call (memory bound; 0 = all styles of a view at once).
        workers: CPU threads measuring views in parallel (0 = ``torch.get_num_threads()``).
    """

    render: RenderConfig = field(default_factory=RenderConfig)
    styles: tuple[str, ...] = ()
    measures: tuple[str, ...] = IMAGE_MEASURES
    mesh_measures: bool = True
    n_samples: int = 20000
    fsim_downsample: int = 2
    chunk: int = 8
    workers: int = 0

    def resolved_styles(self) -> list[str]:
        return resolve_styles(list(self.styles) if self.styles else None)

    def key_dict(self) -> dict:
        d = asdict(self)
        d["render"] = self.render.as_dict()
        d["styles"] = self.resolved_styles()
        d["measures"] = list(self.measures)
        d.pop("chunk")  # neither changes the numbers
        d.pop("workers")
        d["version"] = FEATURE_VERSION
        return d



def feature_config(options: Mapping[str, Any] | None = None) -> FeatureConfig:
    """:class:`FeatureConfig` from plain options, as stored in data configs and checkpoints
    (``data.feature_options``): ``size``, ``extent``, ``distance``, ``shadings``, ``styles``,
    ``measures``, ``mesh_measures``, ``n_samples``, ``fsim_downsample``, ``chunk``, ``workers``
    (missing -> the defaults; ``cache_dir`` is ignored)."""
    o = dict(options or {})
    render_kw = {k: o.pop(k) for k in ("size", "extent", "distance") if k in o}
    if "shadings" in o:
        render_kw["shadings"] = tuple(o.pop("shadings"))
    o.pop("cache_dir", None)
    for k in ("styles", "measures"):
        if k in o and o[k] is not None:
            o[k] = tuple(o[k])
    return FeatureConfig(render=RenderConfig(**render_kw), **o)


@dataclass
class ShapeViews:
    """Rendered grey style images of one mesh.

    Attributes:
        images: ``{shading: (S, V, 1, H, W) float32}`` in ``[0, 1]``.
        masks: ``{shading: (V, 1, H, W) bool}``.
        normals: ``{shading: (V, 3, H, W) float32}`` view-space normals.
    """

    images: dict[str, torch.Tensor]
    masks: dict[str, torch.Tensor]
    normals: dict[str, torch.Tensor]


def render_views(mesh, cfg: FeatureConfig | None = None, device=None, rgb: bool = False) -> ShapeViews:
    """Render every style x view x shading of ``mesh`` (grey unless ``rgb``); point clouds as points."""
    cfg = cfg or FeatureConfig()
    if is_point_source(mesh):  # a point cloud, splatted in its own frame (lit3d.render.splat)
        from lit3d.render.points import load_points
        from lit3d.render.splat import render_point_gbuffers

        gbs = render_point_gbuffers(load_points(mesh), cfg.render)
    else:
        gbs = render_gbuffers(mesh, cfg.render)
    names = cfg.resolved_styles()
    images, masks, normals = {}, {}, {}
    for shading, gb in gbs.items():
        gb = gb.to(device) if device is not None else gb
        images[shading] = apply_styles(gb.normals, gb.mask, names, grey=not rgb)
        masks[shading] = gb.mask
        normals[shading] = gb.normals
    return ShapeViews(images, masks, normals)


def _crop_box(masks: torch.Tensor, margin: int) -> tuple[int, int, int, int]:
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
            must be at least ``_CROP_MARGIN`` pixels from a window side that is not a
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


def image_measures(a: torch.Tensor, b: torch.Tensor, mask_a: torch.Tensor, mask_b: torch.Tensor,
                   measures=IMAGE_MEASURES, fsim_downsample: int = 2, crop: bool = True) -> dict[str, torch.Tensor]:
    """Every image measure for a batch of grey full-canvas image pairs.

    Args:
        a, b: ``(N, 1, H, W) float32`` reference and distorted images in ``[0, 1]``
            (black background outside the masks).
        mask_a, mask_b: ``(N, 1, H, W) bool`` foreground masks.
        measures: subset of :data:`IMAGE_MEASURES`.
        crop: use the bounding-box shortcut (see the module doc): exact for every
            measure but FSIM, whose crop form is an approximation.

    Returns:
        ``{measure: (N,) float32}``.
    """
    h, w = a.shape[-2:]
    if not crop:
        return pair_measures(a, b, mask_a, mask_b, (0, 0, h, w), measures, fsim_downsample)
    y0, y1, x0, x1 = _crop_box(torch.cat([mask_a, mask_b]), _CROP_MARGIN)
    return pair_measures(a[..., y0:y1, x0:x1], b[..., y0:y1, x0:x1], mask_a[..., y0:y1, x0:x1],
                         mask_b[..., y0:y1, x0:x1], (y0, x0, h, w), measures, fsim_downsample)


def _view_measures(ga, gb, v: int, names: list[str], cfg: FeatureConfig) -> dict[str, torch.Tensor]:
    """Every measure of every style for view ``v`` of two G-buffers: ``{measure: (S,) float32 cpu}``.

    The styles are shaded on the view's crop only (union of both masks + ``_CROP_MARGIN``).
    """
    hh, ww = ga.mask.shape[-2:]
    y0, y1, x0, x1 = _crop_box(torch.cat([ga.mask[v:v + 1], gb.mask[v:v + 1]]), _CROP_MARGIN)
    ma, mb = ga.mask[v:v + 1, :, y0:y1, x0:x1], gb.mask[v:v + 1, :, y0:y1, x0:x1]
    ia = apply_styles(ga.normals[v:v + 1, :, y0:y1, x0:x1], ma, names, grey=True)[:, 0]  # (S, 1, h, w)
    ib = apply_styles(gb.normals[v:v + 1, :, y0:y1, x0:x1], mb, names, grey=True)[:, 0]
    step = cfg.chunk if cfg.chunk > 0 else len(names)
    out: dict[str, list[torch.Tensor]] = {}
    for i in range(0, len(names), step):
        j = min(i + step, len(names))
        res = pair_measures(ia[i:j], ib[i:j], ma, mb, (y0, x0, hh, ww), cfg.measures, cfg.fsim_downsample)
        for k, t in res.items():
            out.setdefault(k, []).append(t.float().cpu())
    return {k: torch.cat(t) for k, t in out.items()}


def content_key(ref_hash: str, dist_hash: str, cfg: FeatureConfig) -> str:
    """Cache key: SHA-256 of both mesh hashes and the feature configuration."""
    blob = json.dumps({"ref": ref_hash, "dist": dist_hash, "cfg": cfg.key_dict()}, sort_keys=True)
    return hashlib.sha256(blob.encode()).hexdigest()


def default_cache_dir() -> Path:
    """``$LIT3D_CACHE/features`` or ``~/.cache/lit3d/features``."""
    root = os.environ.get("LIT3D_CACHE") or os.path.join(os.path.expanduser("~"), ".cache", "lit3d")
    return Path(root) / "features"


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
        return overall_score(self.features)


def overall_score(features: dict[str, float], measure: str = "mask_ssim") -> float:
    """The unlearned score: mean of ``measure/<style>/<shading>`` (default Mask-SSIM).

    Colour-less tables: the mean over every style and shading. Tables with colour styles
    (:data:`lit3d.render.colour_styles.COLOUR_STYLES`: coloured point clouds or meshes): the
    mean over the colour styles only, i.e. over the images an observer of the coloured shape
    sees (its colours, silhouette and, in the lit styles, the shading of its geometry); the
    MatCap styles stay in the table as features for the learned score. (Until this revision the
    two blocks were weighted equally; README "Point clouds, colour and CPCD2" gives both
    figures and says which data the choice was made on.)
    """
    from lit3d.render.colour_styles import COLOUR_STYLES

    geo, col = [], []
    for k, v in features.items():
        if k.split("/")[0] == measure and k.count("/") == 2:
            (col if k.split("/")[1] in COLOUR_STYLES else geo).append(v)
    if not geo and not col:
        raise ValueError(f"no {measure}/* features in the table")
    return float(np.mean(col if col else geo))


def feature_table(ref, dist, cfg: FeatureConfig | None = None, *, cache_dir: str | os.PathLike | None = None,
                  device=None, keep_views: bool = False) -> FeatureTable:
    """Compute (or load from cache) the feature table of a shape pair.

    Two point clouds (:func:`lit3d.render.points.is_point_source`) are rendered as points
    (:func:`lit3d.features.points.point_feature_table`; ``keep_views`` is ignored there);
    everything else goes through :func:`lit3d.render.convert.to_mesh` and the mesh G-buffer.

    Args:
        ref, dist: anything :func:`lit3d.render.convert.to_mesh` accepts, or two point clouds.
        cfg: feature configuration.
        cache_dir: folder of cached JSON tables (None: no caching).
        device: torch device for the measures (default CPU).
        keep_views: keep the rendered images in the result (disables the cache read).

    Returns:
        :class:`FeatureTable`.
    """
    cfg = cfg or FeatureConfig()
    if is_point_source(ref) and is_point_source(dist):  # native point rendering, no meshing
        from lit3d.features.points import point_feature_table

        return point_feature_table(ref, dist, cfg, cache_dir=cache_dir, device=device)
    mref, mdist = to_mesh(ref), to_mesh(dist)
    key = content_key(mesh_hash(mref), mesh_hash(mdist), cfg)
    path = Path(cache_dir) / f"{key}.json" if cache_dir is not None else None
    if path is not None and path.is_file() and not keep_views:
        try:
            data = json.loads(path.read_text())
            if data.get("key") == key:
                return FeatureTable({k: float(v) for k, v in data["features"].items()}, key, cached=True)
        except (OSError, ValueError, KeyError):
            pass  # unreadable cache entry: recompute and overwrite
    names = cfg.resolved_styles()
    feats: dict[str, float] = {}
    per_view: dict[str, np.ndarray] = {}
    on_cpu = device is None or torch.device(device).type == "cpu"
    workers = (cfg.workers if cfg.workers > 0 else torch.get_num_threads()) if on_cpu else 1
    pool = None
    prev_threads = torch.get_num_threads()
    if on_cpu:
        # coarse-grained parallelism only: whole views per worker thread, one intra-op thread
        # each (also with workers=1). Per-op OpenMP teams on small crops stall badly on a busy
        # machine: measured on a loaded 2-core CPU, workers=1 with 2 intra-op threads took
        # 18-88 s for the 256^2 table that takes about 5 s with one thread.
        torch.set_num_threads(1)
    if workers > 1:
        from concurrent.futures import ThreadPoolExecutor

        pool = ThreadPoolExecutor(workers, initializer=torch.set_num_threads, initargs=(1,))
    try:
        pending = []
        for shading in cfg.render.shadings:
            # render shading by shading, so the workers measure while the next pass rasterises
            one = replace(cfg.render, shadings=(shading,))
            ga, gb = render_gbuffers(mref, one)[shading], render_gbuffers(mdist, one)[shading]
            if device is not None:
                ga, gb = ga.to(device), gb.to(device)
            for v in range(ga.mask.shape[0]):
                args = (ga, gb, v, names, cfg)
                pending.append((shading, v, pool.submit(_view_measures, *args) if pool else _view_measures(*args)))
        parts: dict[tuple[str, str], torch.Tensor] = {}
        n_views = {}
        for shading, v, res in pending:
            res = res.result() if pool else res
            n_views[shading] = max(n_views.get(shading, 0), v + 1)
            for k, t in res.items():
                parts.setdefault((shading, k), {})[v] = t
    finally:
        if pool is not None:
            pool.shutdown(wait=True)
        torch.set_num_threads(prev_threads)
    for (shading, k), by_view in parts.items():
        vals = torch.stack([by_view[v] for v in range(n_views[shading])], 1)  # (S, V)
        for j, style in enumerate(names):
            name = f"{k}/{style}/{shading}"
            per_view[name] = vals[j].numpy()
            feats[name] = float(vals[j].double().mean())
    va = vb = None
    if keep_views:
        va, vb = render_views(mref, cfg, device), render_views(mdist, cfg, device)
    if cfg.mesh_measures:
        feats.update(chamfer_hausdorff(mref, mdist, cfg.n_samples))
    if path is not None:
        from lit3d.utils.io import write_json

        write_json(path, {"key": key, "config": cfg.key_dict(), "features": feats})
    return FeatureTable(feats, key, cached=False, per_view=per_view, views=(va, vb) if keep_views else None)
