"""The candidates the fusion is chosen among, fixed before any correlation is seen: feature sets, their
orientation and the anchor (:mod:`lit3d.quality.fusion`). One source for ``lit3d-train`` (the
``quality_fusion`` task) and the CPCD2 study (``studies/quality/cpcd2_study.py``).

Feature sets (a priori: what the field measures on coloured point clouds):

- ``points``: Y-PSNR, D1/D2-PSNR, PointSSIM colour and geometry, PCQM;
- ``renders``: CIEDE2000, window Mask-SSIM and piq's measures of the colour renders (first shading);
- ``points+renders``: both.

Candidates: ridge with non-negative weights on each set (:class:`~lit3d.quality.fusion.LinearFusion`)
and, when the anchor is in the table, the anchored fusion with each set as corrections
(:class:`~lit3d.quality.fusion.AnchoredFusion`; anchor PCQM, the field's published colour-aware measure).
"""
from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

from lit3d.quality.fusion import KINDS, AnchoredFusion, LinearFusion

LOWER_IS_BETTER = ("mse", "rmse", "canny", "hausdorff", "chamfer", "d1_mse", "d2_mse", "y_mse", "pcqm", "ciede2000",
                   "gmsd", "mdsi")
FEATURE_SETS: dict[str, tuple[str, ...]] = {
    "points": ("y_psnr", "d1_psnr", "d2_psnr", "pointssim_colour", "pointssim_geometry", "pcqm"),
    "renders": ("ciede2000/matcap_rgb/flat", "ciede2000/albedo_rgb/flat", "mask_ssim_window/matcap_rgb/flat",
                "mask_ssim_window/albedo_rgb/flat", "fsimc/matcap_rgb/flat", "gmsd/matcap_rgb/flat",
                "mdsi/matcap_rgb/flat", "vsi/matcap_rgb/flat", "haarpsi/matcap_rgb/flat", "vif/matcap_rgb/flat"),
}
FEATURE_SETS["points+renders"] = FEATURE_SETS["points"] + FEATURE_SETS["renders"]
ANCHOR = "pcqm"


def orientation(name: str) -> float:
    """+1 when a larger value of feature ``name`` (``measure[/style/shading]``) means better quality, -1 otherwise."""
    head = name.split("/")[0]
    return -1.0 if head in LOWER_IS_BETTER or head.startswith("pcqm_") else 1.0


def fusion_candidates(names: Sequence[str], sets: Mapping[str, Sequence[str]] | None = None,
                      anchor: str | None = ANCHOR) -> dict[str, Callable[[], Any]]:
    """``{"<kind>:<set>": factory of an unfitted model}`` over the features of ``sets`` (default
    :data:`FEATURE_SETS`) that ``names`` holds; ``anchor`` None (or absent from ``names``): no anchored ones."""
    sets = FEATURE_SETS if sets is None else sets
    names = set(names)
    out: dict[str, Callable[[], Any]] = {}
    for set_name, feats in sets.items():
        have = [f for f in feats if f in names]
        if have:
            signs = [orientation(f) for f in have]
            for kind in KINDS:
                out[f"{kind}:{set_name}"] = lambda have=have, signs=signs, kind=kind: LinearFusion(have, signs, kind)
    if anchor and anchor in names:
        for set_name, feats in sets.items():
            have = [f for f in feats if f in names and f != anchor]
            out[f"anchored:{anchor}+{set_name}"] = lambda have=have: AnchoredFusion(
                anchor, orientation(anchor), have, [orientation(f) for f in have])
    return out
