"""The quality part of ``make demo``: one reference shape, a few distorted versions, ``lit3d-score``.

``scripts/demo_quality.sh`` runs, in a folder ``OUT`` (from the checkout, with lit3d installed)::

    python scripts/demo_quality.py prepare OUT [--ref MESH]  # OUT/meshes/*.obj, OUT/pairs.tsv
    lit3d-score OUT/meshes/reference.obj OUT/meshes/<name>.obj --json --save-views OUT/views/<name>
        > OUT/scores/<name>.json                             # once per distorted version
    python scripts/demo_quality.py report OUT                # OUT/results.md, OUT/quality_demo.png

The reference is ``--ref`` (any mesh ``lit3d-score`` reads; vertices split by per-corner normals or
texture coordinates are merged first, so that a distortion moves the surface, not the seams) or the
built-in procedural shape ``bumpy`` (smooth body, bumps on one hemisphere). The distortions are
those of the synthetic quality set (:mod:`datamodules.quality.distortions`), at one level each:
what the score of each says is how visible the damage is in the renders (1 = identical).
"""
from __future__ import annotations

import argparse
import io
import json
import sys
from pathlib import Path

import numpy as np
import torch

from datamodules.quality.distortions import distort
from datamodules.quality.quality_shapes import procedural_shape
from lit3d.features.table import FeatureConfig, render_views
from lit3d.metrics.image import ssim_map, to_grey
from lit3d.render.convert import to_mesh
from lit3d.render.gbuffer import RenderConfig
from lit3d.utils import quiet
from lit3d.utils.checkpoints import first_line
from lit3d.utils.figures import labelled_grid
from lit3d.utils.io import atomic_write_bytes, atomic_write_text
from lit3d.utils.tables import fmt, markdown_table

# name -> (distortion kind, level index into datamodules.quality.distortions.LEVELS, description)
DISTORTIONS: dict[str, tuple[str, int, str]] = {
    "noise_mild": ("noise", 0, "normal noise, 0.2% of the diagonal"),
    "noise_strong": ("noise", 2, "normal noise, 0.8% of the diagonal"),
    "smooth": ("taubin", 2, "Taubin smoothing, 30 iterations"),
    "simplify": ("simplify", 3, "decimated to 6% of the faces"),
    "quantize": ("quantize", 1, "coordinates quantised to 8 bits"),
}
PROG = "demo_quality.py"
FIGURE_STYLE = "clay_studio"
FIGURE_VIEWS = (0, 4, 8)


def reference_mesh(ref: str | None):
    """The demo's reference: ``ref`` (vertices merged) or the procedural ``bumpy`` shape."""
    if ref is None:
        return procedural_shape("bumpy"), "procedural shape 'bumpy' (built in)"
    mesh = to_mesh(ref)
    mesh.merge_vertices(merge_tex=True, merge_norm=True)
    return mesh, str(ref)


def prepare(out: Path, ref: str | None = None) -> list[tuple[str, Path]]:
    """Write ``out/meshes/reference.obj`` and one ``<name>.obj`` per distortion; ``out/pairs.tsv``
    lists ``name, path, description``. Returns ``[(name, path)]``."""
    mesh, source = reference_mesh(ref)
    meshes = out / "meshes"
    meshes.mkdir(parents=True, exist_ok=True)
    ref_path = meshes / "reference.obj"
    mesh.export(ref_path)
    pairs, lines = [], [f"reference\t{ref_path}\t{source}"]
    for name, (kind, level, text) in DISTORTIONS.items():
        path = meshes / f"{name}.obj"
        distort(mesh, kind, level, seed=0).export(path)
        pairs.append((name, path))
        lines.append(f"{name}\t{path}\t{text}")
    atomic_write_text(out / "pairs.tsv", "\n".join(lines) + "\n")
    return pairs


def _pairs(out: Path) -> tuple[tuple[Path, str], list[tuple[str, Path, str]]]:
    path = out / "pairs.tsv"
    rows = [ln.split("\t") for ln in path.read_text().splitlines() if ln.strip()]
    bad = [i for i, r in enumerate(rows, 1) if len(r) != 3]
    if not rows or rows[0][0] != "reference" or bad:
        raise ValueError(f"{path}: not the list that 'prepare' writes (name, path, description per line, "
                         f"reference first{f'; line {bad[0]} has not 3 fields' if bad else ''})")
    (_, ref, source), rest = rows[0], rows[1:]
    return (Path(ref), source), [(n, Path(p), d) for n, p, d in rest]


def _mean(features: dict[str, float], measure: str) -> float:
    vals = [v for k, v in features.items() if k.split("/")[0] == measure and k.count("/") == 2]
    return sum(vals) / len(vals) if vals else float("nan")


def read_score(path: Path, name: str) -> dict:
    """The ``lit3d-score --json`` output at ``path``; FileNotFoundError or ValueError naming the file when
    it is missing or is not that output (not JSON, or no ``overall_score``, ``features`` and ``config``)."""
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no lit3d-score output for '{name}' (run lit3d-score first)")
    try:
        score = json.loads(path.read_text())
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ValueError(f"{path}: not lit3d-score --json output ({first_line(exc)})") from None
    missing = [k for k in ("overall_score", "features", "config") if not isinstance(score, dict) or k not in score]
    if missing:
        raise ValueError(f"{path}: not lit3d-score --json output (no {', '.join(missing)})")
    return score


def report(out: Path) -> str:
    """``out/results.md`` (one row per distorted version, best first) and ``out/quality_demo.png``
    from the ``lit3d-score --json`` outputs in ``out/scores/``. Returns the markdown."""
    (ref, source), pairs = _pairs(out)
    scores = {name: read_score(out / "scores" / f"{name}.json", name) for name, _path, _text in pairs}
    order = sorted(pairs, key=lambda p: -scores[p[0]]["overall_score"])
    rows = []
    for rank, (name, path, text) in enumerate(order, 1):
        feats = scores[name]["features"]
        rows.append([str(rank), f"`{path.name}`", text, fmt(scores[name]["overall_score"]),
                     fmt(_mean(feats, "ssim")), fmt(_mean(feats, "ms_ssim")), fmt(_mean(feats, "psnr"), 1),
                     fmt(feats.get("chamfer"), 4), fmt(feats.get("hausdorff"), 4)])
    cfg = next(iter(scores.values()))["config"]
    text = (
        "# Quality demo: one reference, distorted versions, scored by rendering\n\n"
        f"Reference: {source} (`{ref}`). Each distorted version was scored against it with\n"
        f"`lit3d-score reference.obj <name>.obj --json --save-views views/<name>`: renders from 12\n"
        f"views at {cfg['render']['size']} px in {len(cfg['styles'])} MatCap styles "
        f"({', '.join(cfg['styles'])}), flat and smooth shading, compared image by image.\n"
        "Score = mean Mask-SSIM (1 = identical renders; lower = more visible damage); the other image\n"
        "measures are means over styles, shadings and views; Chamfer and Hausdorff are on surface samples\n"
        "(unit bounding box). Contact sheets: `views/<name>/contact_<shading>.png`; figure: `quality_demo.png`.\n\n"
        + markdown_table(["rank", "distorted version", "distortion", "score (Mask-SSIM)", "SSIM", "MS-SSIM",
                          "PSNR (dB)", "Chamfer", "Hausdorff"], rows) + "\n")
    atomic_write_text(out / "results.md", text)
    figure(out, ref, source, [(n, p, d, scores[n]) for n, p, d in order])
    return text


def figure(out: Path, ref: Path, source: str, rows: list[tuple[str, Path, str, dict]]) -> Path:
    """``out/quality_demo.png``: the reference and each distorted version (best score first) in
    three views, with the SSIM map of the first view against the reference."""
    cfg = FeatureConfig(render=RenderConfig(size=256, shadings=("smooth",)), styles=(FIGURE_STYLE,))

    def views(path: Path) -> torch.Tensor:  # (V, 3, H, W) in [0, 1]
        return render_views(to_mesh(path), cfg, rgb=True).images["smooth"][0]

    def cell(img: torch.Tensor) -> np.ndarray:
        return (img.clamp(0, 1).permute(1, 2, 0).numpy() * 255 + 0.5).astype(np.uint8)

    ref_views = views(ref)
    white = np.full((256, 256, 3), 255, np.uint8)
    grid = [{"label": "reference\n" + _wrap(Path(source).name if "/" in source else source),
             "cells": [cell(ref_views[v]) for v in FIGURE_VIEWS] + [white]}]
    for name, _path, text, score in rows:
        dist_views = views(_path)
        smap = ssim_map(to_grey(ref_views[FIGURE_VIEWS[0]][None]), to_grey(dist_views[FIGURE_VIEWS[0]][None]))
        feats = score["features"]
        label = (f"{name}\n{_wrap(text)}\nscore {score['overall_score']:.3f} (Mask-SSIM)\n"
                 f"PSNR {_mean(feats, 'psnr'):.1f} dB")
        grid.append({"label": label, "cells": [cell(dist_views[v]) for v in FIGURE_VIEWS]
                     + [cell(smap[0].clamp(0, 1).expand(3, -1, -1))]})
    columns = [f"view {v + 1} of 12" for v in FIGURE_VIEWS] + ["SSIM map, view 1"]
    img = labelled_grid(grid, columns, "lit3d-score: a reference and distorted versions, best score first "
                                       "(1 = identical)", left=250)
    buf = io.BytesIO()
    img.save(buf, format="PNG")
    return atomic_write_bytes(out / "quality_demo.png", buf.getvalue())


def _wrap(text: str, width: int = 26) -> str:
    words, lines, line = text.split(), [], ""
    for w in words:
        if line and len(line) + 1 + len(w) > width:
            lines.append(line)
            line = w
        else:
            line = f"{line} {w}".strip()
    return "\n".join([*lines, line])


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog=PROG, description=__doc__.split("\n\n")[0])
    sub = p.add_subparsers(dest="cmd", required=True)
    pp = sub.add_parser("prepare", help="write the reference and distorted meshes and pairs.tsv")
    pp.add_argument("out", type=Path)
    pp.add_argument("--ref", default=None, help="reference mesh (default: the procedural shape 'bumpy')")
    pr = sub.add_parser("report", help="results.md and quality_demo.png from the lit3d-score JSON outputs")
    pr.add_argument("out", type=Path)
    args = p.parse_args(argv)
    quiet.install()
    try:
        if args.cmd == "prepare":
            for name, path in prepare(args.out, args.ref):
                print(f"{name}\t{path}")
        else:
            print(report(args.out))
    except (OSError, ValueError) as exc:  # a missing or bad score file or pairs.tsv, an unreadable reference mesh
        print(f"{PROG} {args.cmd}: error: {first_line(exc, type(exc).__name__)}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
