"""Feature table of a (reference, distorted) mesh pair: measure x style x shading, 12-view means.

Pipeline per mesh: ``to_mesh`` -> normalise -> one G-buffer pass per view and
shading (:mod:`lit3d.render.gbuffer`) -> all styles as one batched MatCap
look-up (:mod:`lit3d.render.styles`). Then every image measure runs once over
the whole batch of ``shadings x styles x views`` grey image pairs (in chunks of
``chunk`` images to bound memory) and is averaged over the views.

Feature names are ``measure/style/shading`` (``mask_ssim_window/ceramic_lightbulb/flat``)
plus the 3-D features ``chamfer`` and ``hausdorff``. Images are grey (BT.601 luma
of the RGB MatCap) in ``[0, 1]`` on a black background. Two point clouds go to
:func:`lit3d.features.point_table.point_feature_table` instead (rendered as points).

The measures use exact crop shortcuts (see :mod:`lit3d.features.view_measures`, which also holds
:class:`FeatureConfig`, :class:`FeatureTable`, the cache and the worker threads that this
module and :mod:`lit3d.features.point_table` share; they are re-exported here).

Tables are cached on disk as JSON (atomic temp file + rename) keyed by the SHA-256
of both meshes' vertex/face arrays and the feature configuration.
"""
from __future__ import annotations

import os
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch

from lit3d.features.cache import cache_path, read_cached_table, write_cached_table
from lit3d.features.config import (
    CROP_MARGIN, FEATURE_VERSION, IMAGE_MEASURES, MESH_MEASURES, FeatureConfig, FeatureTable, ShapeViews, content_key,
    feature_config, overall_score)
from lit3d.features.view_measures import crop_box, pair_measures, view_measures
from lit3d.features.workers import view_workers
from lit3d.features.point_table import point_feature_table
from lit3d.metrics.mesh import chamfer_hausdorff
from lit3d.render.convert import mesh_hash, to_mesh
from lit3d.render.gbuffer import render_gbuffers
from lit3d.render.point_clouds import is_point_source, load_points
from lit3d.render.splat import render_point_gbuffers
from lit3d.render.styles import apply_styles

__all__ = [  # with the names of lit3d.features.config that callers have always imported from here
    "FEATURE_VERSION", "IMAGE_MEASURES", "MESH_MEASURES", "FeatureConfig", "FeatureTable", "ShapeViews",
    "content_key", "default_cache_dir", "feature_config", "feature_table", "image_measures", "overall_score",
    "pair_measures", "render_views",
]


def render_views(mesh, cfg: FeatureConfig | None = None, device=None, rgb: bool = False) -> ShapeViews:
    """Render every style x view x shading of ``mesh`` (grey unless ``rgb``); point clouds as points."""
    cfg = cfg or FeatureConfig()
    if is_point_source(mesh):  # a point cloud, splatted in its own frame (lit3d.render.splat)
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


def image_measures(a: torch.Tensor, b: torch.Tensor, mask_a: torch.Tensor, mask_b: torch.Tensor,
                   measures=IMAGE_MEASURES, fsim_downsample: int = 2, crop: bool = True) -> dict[str, torch.Tensor]:
    """Every image measure for a batch of grey full-canvas image pairs.

    Args:
        a, b: ``(N, 1, H, W) float32`` reference and distorted images in ``[0, 1]``
            (black background outside the masks).
        mask_a, mask_b: ``(N, 1, H, W) bool`` foreground masks.
        measures: subset of :data:`IMAGE_MEASURES`.
        crop: use the bounding-box shortcut (see :mod:`lit3d.features.view_measures`): exact for every
            measure but FSIM, whose crop form is an approximation.

    Returns:
        ``{measure: (N,) float32}``.
    """
    h, w = a.shape[-2:]
    if not crop:
        return pair_measures(a, b, mask_a, mask_b, (0, 0, h, w), measures, fsim_downsample)
    y0, y1, x0, x1 = crop_box(torch.cat([mask_a, mask_b]), CROP_MARGIN)
    return pair_measures(a[..., y0:y1, x0:x1], b[..., y0:y1, x0:x1], mask_a[..., y0:y1, x0:x1],
                         mask_b[..., y0:y1, x0:x1], (y0, x0, h, w), measures, fsim_downsample)


def default_cache_dir() -> Path:
    """``$LIT3D_CACHE/features`` or ``~/.cache/lit3d/features``."""
    root = os.environ.get("LIT3D_CACHE") or os.path.join(os.path.expanduser("~"), ".cache", "lit3d")
    return Path(root) / "features"


def feature_table(ref, dist, cfg: FeatureConfig | None = None, *, cache_dir: str | os.PathLike | None = None,
                  device=None, keep_views: bool = False) -> FeatureTable:
    """Compute (or load from cache) the feature table of a shape pair.

    Two point clouds (:func:`lit3d.render.point_clouds.is_point_source`) are rendered as points
    (:func:`lit3d.features.point_table.point_feature_table`; ``keep_views`` is ignored there);
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
        return point_feature_table(ref, dist, cfg, cache_dir=cache_dir, device=device)
    mref, mdist = to_mesh(ref), to_mesh(dist)
    key = content_key(mesh_hash(mref), mesh_hash(mdist), cfg)
    path = cache_path(cache_dir, key)
    cached = None if keep_views else read_cached_table(path, key)
    if cached is not None:
        return cached
    names = cfg.resolved_styles()
    feats: dict[str, float] = {}
    per_view: dict[str, np.ndarray] = {}
    with view_workers(cfg.workers, device) as submit:
        pending = []
        for shading in cfg.render.shadings:
            # render shading by shading, so the workers measure while the next pass rasterises
            one = replace(cfg.render, shadings=(shading,))
            ga, gb = render_gbuffers(mref, one)[shading], render_gbuffers(mdist, one)[shading]
            if device is not None:
                ga, gb = ga.to(device), gb.to(device)
            for v in range(ga.mask.shape[0]):
                pending.append((shading, v, submit(view_measures, ga, gb, v, names, cfg)))
        parts: dict[tuple[str, str], dict[int, torch.Tensor]] = {}
        n_views = {}
        for shading, v, res in pending:
            n_views[shading] = max(n_views.get(shading, 0), v + 1)
            for k, t in res.result().items():
                parts.setdefault((shading, k), {})[v] = t
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
    write_cached_table(path, key, cfg, feats)
    return FeatureTable(feats, key, cached=False, per_view=per_view, views=(va, vb) if keep_views else None)
