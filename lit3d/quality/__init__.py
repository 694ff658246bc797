"""Rendering-based 3-D shape quality (thesis ch. 4): feature tables of mesh pairs."""
from lit3d.quality.features import (  # noqa: F401
    IMAGE_MEASURES,
    MESH_MEASURES,
    FeatureConfig,
    FeatureTable,
    feature_config,
    feature_table,
    image_measures,
    overall_score,
    render_views,
)
