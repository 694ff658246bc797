"""``lit3d-score REF DIST``: rendering-based quality features and score of a shape pair.

Examples::

    lit3d-score bunny.obj bunny_noisy.ply                 # summary + overall score
    lit3d-score target.npz prediction.npz --json          # every feature as JSON
    lit3d-score a.obj b.obj --styles jade,toon --size 128 --save-views out/

The overall score is the mean Mask-SSIM over styles, shadings and the 12 views
(1 = identical renders). ``--ckpt`` (a trained quality model) is not supported
yet. Bad inputs end with one line naming the file and exit status 2.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

EXIT_USER = 2


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="lit3d-score", description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("ref", help="reference shape (.obj .off .ply .stl .glb, points .xyz, voxel/SDF .npz)")
    p.add_argument("dist", help="distorted / predicted shape (same formats)")
    p.add_argument("--size", type=int, default=256, help="render size in pixels (default 256)")
    p.add_argument("--styles", default="all", help="'all' or comma-separated style names")
    p.add_argument("--json", action="store_true", help="print every feature as JSON on stdout")
    p.add_argument("--save-views", metavar="DIR", help="write contact sheets (views, styles, SSIM maps) here")
    p.add_argument("--ckpt", metavar="PATH", help="trained quality model (not supported yet)")
    p.add_argument("--no-cache", action="store_true", help="do not read or write the feature cache")
    p.add_argument("--device", default=None, help="torch device for the measures (default cpu)")
    p.add_argument("--debug", action="store_true", help="show full tracebacks")
    return p


def _summary(table, ref: str, dist: str, seconds: float) -> str:
    from lit3d.reports.tables import markdown_table

    feats = table.features
    measures: dict[str, dict[str, list[float]]] = {}
    for k, v in feats.items():
        if k.count("/") == 2:
            m, _, sh = k.split("/")
            measures.setdefault(m, {}).setdefault(sh, []).append(v)
    shadings = sorted({sh for d in measures.values() for sh in d})
    rows = [[m] + [f"{sum(d[sh]) / len(d[sh]):.4f}" if sh in d else "-" for sh in shadings]
            for m, d in measures.items()]
    lines = [f"reference: {ref}", f"distorted: {dist}",
             markdown_table(["measure (mean over styles, 12 views)"] + shadings, rows)]
    for k in ("chamfer", "hausdorff"):
        if k in feats:
            lines.append(f"{k}: {feats[k]:.5f}")
    lines.append(f"features: {len(feats)}  ({'cached' if table.cached else f'{seconds:.1f} s'})")
    lines.append(f"overall score (mean Mask-SSIM): {table.overall_score():.4f}")
    return "\n".join(lines)


def save_contact_sheets(ref, dist, cfg, out_dir: str | Path, thumb: int = 64) -> list[Path]:
    """Write one PNG per shading: rows = styles; columns = 12 reference views, 12 distorted
    views, 12 SSIM maps (grey, white = 1). Returns the written paths."""
    import numpy as np
    import torch
    import torch.nn.functional as F
    from PIL import Image

    from lit3d.metrics.image import ssim_map, to_grey
    from lit3d.quality.features import render_views
    from lit3d.utils.io import atomic_write_bytes

    out = Path(out_dir)
    va, vb = render_views(ref, cfg, rgb=True), render_views(dist, cfg, rgb=True)
    paths = []
    for shading in va.images:
        a, b = va.images[shading], vb.images[shading]  # (S, V, 3, H, W)
        s, v = a.shape[:2]
        fa, fb = a.flatten(0, 1), b.flatten(0, 1)
        smap = ssim_map(to_grey(fa), to_grey(fb)).clamp(0, 1).expand(-1, 3, -1, -1)
        tiles = torch.stack([fa, fb, smap]).flatten(0, 1)  # (3*S*V, 3, H, W)
        tiles = F.interpolate(tiles, size=(thumb, thumb), mode="area").view(3, s, v, 3, thumb, thumb)
        grid = tiles.permute(1, 4, 0, 2, 5, 3).reshape(s * thumb, 3 * v * thumb, 3)
        img = Image.fromarray((grid.clamp(0, 1).numpy() * 255 + 0.5).astype(np.uint8))
        import io

        buf = io.BytesIO()
        img.save(buf, format="PNG")
        paths.append(atomic_write_bytes(out / f"contact_{shading}.png", buf.getvalue()))
    return paths


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    try:
        return _run(args)
    except KeyboardInterrupt:
        print("lit3d-score: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:
        if args.debug:
            raise
        from lit3d.render.convert import ShapeError

        msg = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        user = isinstance(exc, (ShapeError, ValueError, FileNotFoundError, NotImplementedError))
        kind = "error" if user else f"internal error ({type(exc).__name__}; rerun with --debug)"
        print(f"lit3d-score: {kind}: {msg}", file=sys.stderr)
        return EXIT_USER if user else 1


def _run(args) -> int:
    from lit3d.render.convert import to_mesh

    if args.ckpt:
        raise NotImplementedError(f"{args.ckpt}: --ckpt (learned MOS prediction) is not yet supported; "
                                  "run without it for the mean Mask-SSIM score")
    if not 16 <= args.size <= 4096:
        raise ValueError(f"--size {args.size}: expected 16..4096 pixels")
    # shapes first: a bad file is reported before torch and the renderer are imported (about 1 s, not 10)
    ref = to_mesh(args.ref)
    dist = to_mesh(args.dist)
    from lit3d.quality.features import FeatureConfig, default_cache_dir, feature_table
    from lit3d.render.gbuffer import RenderConfig
    from lit3d.render.styles import resolve_styles

    cfg = FeatureConfig(render=RenderConfig(size=args.size), styles=tuple(resolve_styles(args.styles)))
    t0 = time.perf_counter()
    table = feature_table(ref, dist, cfg, cache_dir=None if args.no_cache else default_cache_dir(),
                          device=args.device)
    seconds = time.perf_counter() - t0
    if args.save_views:
        for p in save_contact_sheets(ref, dist, cfg, args.save_views):
            print(f"wrote {p}", file=sys.stderr)
    if args.json:
        print(json.dumps({"ref": str(args.ref), "dist": str(args.dist), "overall_score": table.overall_score(),
                          "cached": table.cached, "seconds": seconds, "config": cfg.key_dict(),
                          "features": table.features}, indent=2, sort_keys=True))
    else:
        print(_summary(table, args.ref, args.dist, seconds))
    return 0


if __name__ == "__main__":
    sys.exit(main())
