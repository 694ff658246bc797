"""The feature table's configuration and result types, shared by the mesh table (:mod:`lit3d.features.table`)
and the point-cloud table (:mod:`lit3d.features.point_table`): the measure names, :class:`FeatureConfig` (and
:func:`feature_config`, one from plain options), :class:`ShapeViews`, :class:`FeatureTable`, :func:`overall_score` and
the cache key :func:`content_key`."""
from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
import torch

from lit3d.render.colour_styles import COLOUR_STYLES
from lit3d.render.gbuffer import RenderConfig
from lit3d.render.styles import resolve_styles


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
    (``data.feature_tables.options``): ``size``, ``extent``, ``distance``, ``shadings``, ``styles``,
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
