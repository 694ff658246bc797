"""Thesis table 4.5: plain SSIM drifts with the canvas size, Mask-SSIM does not.

One reference/distorted pair is rendered with the shape at a fixed size in
pixels on canvases of 128, 256, 512 and 1024 pixels (the orthographic view
widens with the canvas, so each larger canvas only adds empty background).
Plain SSIM counts the ever larger background (identical in both images) and
creeps towards 1; Mask-SSIM only looks at the shape and stays put.

Run::

    python -m studies.quality.canvas_study --out docs/canvas_study.md

``--ref``/``--dist`` take any shape files; by default a procedural bumpy sphere
and a copy with normal-direction vertex noise are used.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from lit3d.features.table import FeatureConfig, feature_table
from lit3d.render.convert import ShapeError, to_mesh
from lit3d.render.gbuffer import RenderConfig
from lit3d.render.styles import resolve_styles
from lit3d.utils.io import atomic_write_text
from lit3d.utils.tables import markdown_table

DEFAULT_CANVASES = (128, 256, 512, 1024)
DEFAULT_STYLES = ("basic_1", "ceramic_lightbulb", "clay_studio", "metal_shiny", "toon", "lambert_white")


def default_pair(seed: int = 0):
    """A bumpy icosphere and a copy with normal noise (sigma 1% of the box)."""
    import trimesh

    s = trimesh.creation.icosphere(4)
    v = s.vertices
    r = 1.0 + 0.08 * np.sin(5 * v[:, 0]) * np.sin(5 * v[:, 1]) * np.sin(5 * v[:, 2] + 1.0)
    ref = trimesh.Trimesh(v * r[:, None], s.faces, process=False)
    dist = ref.copy()
    g = np.random.default_rng(seed)
    dist.vertices = dist.vertices + dist.vertex_normals * g.normal(0, 0.02, (len(v), 1))
    return ref, dist


def canvas_rows(ref, dist, canvases=DEFAULT_CANVASES, styles=DEFAULT_STYLES, base_canvas: int = 128,
                base_extent: float = 0.9) -> list[dict]:
    """One row per canvas: ``{canvas, shape_px, ssim, mask_ssim, mask_ssim_window, ...}``.

    The view half-width grows as ``base_extent * canvas / base_canvas``, so the shape
    covers the same pixels on every canvas (canvas offsets are whole pixels).
    """
    rows = []
    for c in canvases:
        cfg = FeatureConfig(render=RenderConfig(size=c, extent=base_extent * c / base_canvas), styles=tuple(styles),
                            measures=("mask_ssim", "mask_ssim_window", "mask_ssim_negative", "mask_ssim_merge",
                                      "ssim"), mesh_measures=False, chunk=36)
        f = feature_table(ref, dist, cfg).features
        row = {"canvas": c, "shape_px": round(base_canvas / (2 * base_extent))}
        for m in ("ssim", "mask_ssim", "mask_ssim_window", "mask_ssim_negative", "mask_ssim_merge"):
            row[m] = float(np.mean([v for k, v in f.items() if k.split("/")[0] == m]))
        rows.append(row)
    return rows


def markdown(rows: list[dict]) -> str:
    """The table as markdown, plus the drift (max - min) of each column."""
    cols = ("ssim", "mask_ssim", "mask_ssim_window", "mask_ssim_negative", "mask_ssim_merge")
    body = [[str(r["canvas"]), str(r["shape_px"])] + [f"{r[c]:.4f}" for c in cols] for r in rows]
    body.append(["drift (max-min)", ""] + [f"{max(r[c] for r in rows) - min(r[c] for r in rows):.4f}" for c in cols])
    return ("# Canvas-size study (thesis table 4.5)\n\n"
            "Same pair, shape at a fixed pixel size, growing empty canvas; means over styles, "
            "shadings and 12 views.\n\n"
            + markdown_table(["canvas px", "shape px (unit box)", "SSIM", "Mask-SSIM", "window", "negative",
                              "merge"], body) + "\n")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description="Reproduce thesis table 4.5 (SSIM vs Mask-SSIM over canvas sizes).")
    p.add_argument("--out", required=True, help="markdown file to write")
    p.add_argument("--ref", help="reference shape (default: procedural bumpy sphere)")
    p.add_argument("--dist", help="distorted shape (default: reference + normal noise)")
    p.add_argument("--canvases", default=",".join(map(str, DEFAULT_CANVASES)))
    p.add_argument("--styles", default=",".join(DEFAULT_STYLES), help="comma list or 'all'")
    a = p.parse_args(argv)
    try:
        if a.ref and a.dist:
            ref, dist = to_mesh(a.ref), to_mesh(a.dist)
        else:
            ref, dist = default_pair()
        rows = canvas_rows(ref, dist, tuple(int(c) for c in a.canvases.split(",")), resolve_styles(a.styles))
    except (ShapeError, ValueError) as exc:
        print(f"canvas_study: error: {exc}", file=sys.stderr)
        return 2
    text = markdown(rows)
    atomic_write_text(Path(a.out), text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
