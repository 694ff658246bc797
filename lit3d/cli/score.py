"""``lit3d-score REF DIST``: rendering-based quality features and score of a shape pair (or many: --pairs).

Examples::

    lit3d-score ref.ply distorted.ply                     # coloured clouds: the shipped model's opinion score
    lit3d-score bunny.obj bunny_noisy.ply --unlearned     # summary + unlearned score (mean Mask-SSIM)
    lit3d-score target.npz prediction.npz --json          # every feature as JSON
    lit3d-score a.obj b.obj --styles jade,toon --size 128 --save-views out/
    lit3d-score ref.obj dist.ply --ckpt logs/quality/runs/X/checkpoints/best-059.ckpt
    lit3d-score --pairs pairs.tsv                         # many pairs, one process, one table
    lit3d-score --pairs targets/ predictions/ --json      # files with the same name stem in both folders

Without ``--ckpt`` the score is the shipped quality model's predicted opinion score (MOS 1..5,
trained on CPCD2.0 phil's human ratings of coloured point clouds: ``lit3d.quality.shipped``, card:
https://github.com/lit3d/lit3d/blob/main/docs/quality_model.md) when the pair has the features it uses
(two coloured point clouds, the default 256 px renders); otherwise, and with ``--unlearned``, the unlearned score: the mean
Mask-SSIM over styles, shadings and the 12 views (1 = identical renders). Two point clouds (.xyz, a .ply
without faces, a .zip holding one .ply) are rendered as points, with colour styles when both carry colour (the overall score
is then the mean Mask-SSIM over the colour styles alone; the MatCap styles stay in the
table as features for a learned score) and the D1/D2/Y-PSNR baselines. PLY colours are
read by their declared type (uchar 0-255, float 0-1); NaN colours are refused. --save-views
writes its sheets as one set into a folder checked first (a file, a read-only folder, or a
sheet name that is an input gives one line and exit 2 before anything is rendered).
With ``--ckpt`` (a quality model saved by
``lit3d-train task=quality``) the overall score is the model's prediction instead:
the features are computed with the render size, styles, measures and shadings the
model was trained on (``--size``/``--styles`` are then ignored, with a note), its
SFS-selected features feed the MLP, and the [0, 1] output is mapped back to the
training dataset's score range and direction (e.g. MOS 0-10 for LIRIS/EPFL; the
built-in synthetic set gives an ordinal severity in [0, 1], not an opinion score).
``--pairs FILE.tsv`` (reference<TAB>distorted a line) or ``--pairs REF_DIR DIST_DIR`` (same
name stems) scores many pairs in one process (one start-up, one renderer): a line per pair on
stderr, one table on stdout (``--json``: one document per pair).
Bad inputs end with one line naming the file and exit status 2.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from pathlib import Path

from lit3d.cli.about import allocation_failure, run_argparse_cli, version_line
from lit3d.features import SCORE_SIZE



def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="lit3d-score", description=__doc__.split("\n\n")[0],
                                epilog="\n\n".join(__doc__.split("\n\n")[1:]).replace("``", "'"),
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("ref", nargs="?", help="reference shape (.obj .off .ply .stl .glb, points .xyz/.ply/.zip, "
                                          "voxel/SDF .npz)")
    p.add_argument("dist", nargs="?", help="distorted / predicted shape (same formats)")
    p.add_argument("--pairs", nargs="+", metavar="PATH",
                   help="many pairs in one process, one table out: FILE.tsv (reference<TAB>distorted a line, "
                        "paths relative to the file) or REF_DIR DIST_DIR (files with the same name stem)")
    p.add_argument("--size", type=int, default=None,
                   help=f"render size in pixels (default {SCORE_SIZE}; with --ckpt: the model's; set: the unlearned "
                        "score, the shipped model scores its own renders only)")
    p.add_argument("--styles", default=None,
                   help="'all' (default) or comma-separated style names (with --ckpt: the model's)")
    p.add_argument("--json", action="store_true", help="print every feature as JSON on stdout")
    p.add_argument("--save-views", metavar="DIR", help="write contact sheets (views, styles, SSIM maps) here")
    p.add_argument("--ckpt", metavar="PATH",
                   help="quality model checkpoint (lit3d-train task=quality): print its predicted score")
    p.add_argument("--model", metavar="JSON",
                   help="a quality model file instead of the shipped one (quality_model.json of lit3d-train "
                        "experiment=quality_cpcd2_fusion)")
    p.add_argument("--unlearned", action="store_true",
                   help="print the unlearned score (mean Mask-SSIM) instead of the shipped model's opinion score")
    p.add_argument("--no-cache", action="store_true", help="do not read or write the feature cache")
    p.add_argument("--device", default=None, help="torch device for the measures (default cpu)")
    p.add_argument("--debug", action="store_true", help="show full tracebacks")
    p.add_argument("--version", action="version", version=version_line("lit3d-score"))
    return p


def _summary(table, ref: str, dist: str, seconds: float, prediction: dict | None = None,
             notes: list[str] = ()) -> str:
    from lit3d.utils.tables import markdown_table

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
    for k in ("chamfer", "hausdorff", "d1_psnr", "d2_psnr", "y_psnr", "pointssim_geometry", "pointssim_normal",
              "pointssim_curvature", "pointssim_colour", "pcqm"):
        if k in feats:
            lines.append(f"{k}: {feats[k]:.5f}")
    lines.append(f"features: {len(feats)}  ({'cached' if table.cached else f'{seconds:.1f} s'})")
    lines += [f"note: {n}" for n in notes]
    if prediction is None:
        lines.append(f"overall score (mean Mask-SSIM): {table.overall_score():.4f}")
    else:
        src = prediction["source"]
        lines.append(f"mean Mask-SSIM: {table.overall_score():.4f}")
        lines.append(f"predicted quality (model {src['model']}): {prediction['score']:.4f}")
        lines.append(f"  {src['description']}; model output {src['distortion']:.4f} in [0, 1] "
                     f"(higher = more distorted) from {len(src['features'])} selected features")
    return "\n".join(lines)


def save_contact_sheets(ref, dist, cfg, out_dir: str | Path, thumb: int = 96,
                        names: tuple[str, str] = ("reference", "distorted"), protected=()) -> list[Path]:
    """Write one labelled PNG per shading: rows = styles (named on the left); columns = the 12
    reference views, the 12 distorted views, the 12 SSIM maps (grey, white = 1), each block titled
    (``names``: the two shapes, for the title). Returns the written paths."""
    import io

    import numpy as np
    import torch
    import torch.nn.functional as F
    from PIL import Image, ImageDraw

    from lit3d.metrics.image import ssim_map, to_grey
    from lit3d.features.table import render_views
    from lit3d.utils.figures import font
    from lit3d.utils.io import write_file_set

    out = Path(out_dir)
    styles = cfg.resolved_styles()
    va, vb = render_views(ref, cfg, rgb=True), render_views(dist, cfg, rgb=True)
    left, top, gap = 170, 64, 8  # style-name margin, title + block headers, space between blocks
    sheets: dict[str, bytes] = {}
    for shading in va.images:
        a, b = va.images[shading], vb.images[shading]  # (S, V, 3, H, W)
        s, v = a.shape[:2]
        fa, fb = a.flatten(0, 1), b.flatten(0, 1)
        smap = ssim_map(to_grey(fa), to_grey(fb)).clamp(0, 1).expand(-1, 3, -1, -1)
        tiles = torch.stack([fa, fb, smap]).flatten(0, 1)  # (3*S*V, 3, H, W)
        tiles = F.interpolate(tiles, size=(thumb, thumb), mode="area").view(3, s, v, 3, thumb, thumb)
        block_w = v * thumb
        img = Image.new("RGB", (left + 3 * block_w + 2 * gap, top + s * thumb), "white")
        draw = ImageDraw.Draw(img)
        draw.text((6, 6), f"lit3d-score contact sheet, {shading} shading: {names[0]} vs {names[1]}",
                  fill="black", font=font(18))
        titles = ("reference, 12 views", "distorted, same 12 views", "SSIM map per view (white = identical)")
        for k, title in enumerate(titles):
            block = tiles[k].permute(0, 3, 1, 4, 2).reshape(s * thumb, block_w, 3)  # (S*thumb, V*thumb, 3)
            x = left + k * (block_w + gap)
            img.paste(Image.fromarray((block.clamp(0, 1).numpy() * 255 + 0.5).astype(np.uint8)), (x, top))
            draw.text((x + block_w // 2, top - 14), title, fill="black", font=font(16), anchor="mm")
        for r, name in enumerate(styles[:s]):
            draw.text((6, top + r * thumb + thumb // 2), name, fill="black", font=font(15), anchor="lm")
        buf = io.BytesIO()
        img.save(buf, format="PNG")
        sheets[f"contact_{shading}.png"] = buf.getvalue()
    return write_file_set(out, sheets, protected)  # one set: all sheets or none


def main(argv: list[str] | None = None) -> int:
    return run_argparse_cli("lit3d-score", _parser(), _run, argv)


def _run(args) -> int:
    if args.size is not None and not 16 <= args.size <= 4096:
        raise ValueError(f"--size {args.size}: expected 16..4096 pixels")
    if args.pairs:
        return _run_pairs(args)
    if not (args.ref and args.dist):
        raise ValueError("give two shapes (REF DIST), or --pairs FILE.tsv, or --pairs REF_DIR DIST_DIR")
    if args.save_views:  # before any shape is read or rendered
        from lit3d.utils.io import check_output_dir, check_targets

        check_targets([Path(args.save_views) / f"contact_{sh}.png" for sh in ("flat", "smooth")], _inputs(args))
        check_output_dir(args.save_views, "--save-views")
    # shapes first: a bad file is reported before torch and the renderer are imported (about 1 s, not 10)
    ref, dist = _load_pair(args.ref, args.dist)
    cfg, predictor, notes = _feature_setup(args)
    table, seconds, prediction = _score(args, cfg, predictor, ref, dist)
    if predictor is not None and prediction is None:
        notes.append(_shipped_unusable(predictor, table))
    if args.save_views:
        for p in save_contact_sheets(ref, dist, cfg, args.save_views, names=(args.ref, args.dist),
                                     protected=_inputs(args)):
            print(f"wrote {p}", file=sys.stderr)
    if args.json:
        doc = {**_doc(args.ref, args.dist, table, seconds, prediction), "config": cfg.key_dict()}
        if prediction is not None:
            doc["notes"] = notes
        print(json.dumps(doc, indent=2, sort_keys=True))
    else:
        print(_summary(table, args.ref, args.dist, seconds, prediction, notes))
    return 0


def _run_pairs(args) -> int:
    """``--pairs``: every pair in this one process (one start-up, one renderer), one table on stdout
    (``--json``: ``{"config", "notes", "pairs": [one document per pair]}``), a line per pair on stderr."""
    from lit3d.cli.score_pairs import pairs_table, read_pairs
    from lit3d.utils.files import shown

    if args.ref or args.dist:
        raise ValueError("--pairs names the pairs itself: give no REF DIST with it")
    if args.save_views:
        raise ValueError("--save-views draws one pair: give REF DIST instead of --pairs")
    pairs, notes = read_pairs(args.pairs)  # every file is checked before anything is loaded
    for note in notes:
        print(f"note: {note}", file=sys.stderr)
    cfg, predictor, model_notes = _feature_setup(args)
    docs = []
    for i, (ref_file, dist_file) in enumerate(pairs, 1):
        table, seconds, prediction = _score(args, cfg, predictor, *_load_pair(ref_file, dist_file))
        ref_path, dist_path = shown(ref_file), shown(dist_file)  # a Latin-1 name printed as \xNN escapes
        docs.append(_doc(ref_path, dist_path, table, seconds, prediction))
        if predictor is not None and prediction is None:
            model_notes.append(f"{ref_path} vs {dist_path}: {_shipped_unusable(predictor, table)}")
        took = "cached" if table.cached else f"{seconds:.1f} s"
        print(f"[{i}/{len(pairs)}] {ref_path} vs {dist_path}: {table.overall_score():.4f} ({took})", file=sys.stderr)
    if args.json:
        print(json.dumps({"config": cfg.key_dict(), "notes": notes + model_notes, "pairs": docs}, indent=2,
                         sort_keys=True))
    else:
        print("\n".join([pairs_table(docs)] + [f"note: {n}" for n in model_notes]))
    return 0


def _load_pair(ref: str | Path, dist: str | Path):
    """Two point clouds are rendered as points; anything else as meshes (:func:`to_mesh`)."""
    from lit3d.render.convert import to_mesh
    from lit3d.render.point_clouds import is_point_source, load_points

    if is_point_source(ref) and is_point_source(dist):
        return load_points(ref), load_points(dist)
    return to_mesh(ref), to_mesh(dist)


def _feature_setup(args):
    """``(FeatureConfig, predictor or None, notes)`` from ``--size``/``--styles``, ``--ckpt`` or the shipped model."""
    from lit3d.features.table import FeatureConfig

    cfg = FeatureConfig.rendered(args.size or SCORE_SIZE, args.styles)
    if args.ckpt:
        if args.unlearned or args.model:
            raise ValueError(f"{'--unlearned' if args.unlearned else '--model'} and --ckpt are two scores: give one")
        predictor, cfg, notes = _model_features(args, cfg)
        return cfg, predictor, notes
    if args.unlearned:
        if args.model:
            raise ValueError("--unlearned prints the unlearned score: give it without --model")
        return cfg, None, []
    from lit3d.quality.shipped import load_model_file, load_shipped

    if args.model:
        model = load_model_file(args.model)
        return model.feature_config(), model, []

    if args.size is not None or args.styles is not None:  # the shipped model scores its own renders only
        return cfg, None, []
    shipped = load_shipped()
    return shipped.feature_config(), shipped, []


def _score(args, cfg, predictor, ref, dist):
    """``(feature table, seconds, prediction or None)`` of one loaded pair. The feature cache is
    optional: a cache that cannot be written gives one warning line (once a run), the score is
    computed all the same. Memory that cannot be allocated for the renders is one line naming the
    render size (exit 2)."""
    from lit3d.features.cache import CacheWarning
    from lit3d.features.table import default_cache_dir, feature_table

    t0 = time.perf_counter()
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", CacheWarning)
            table = feature_table(ref, dist, cfg, cache_dir=None if args.no_cache else default_cache_dir(),
                                  device=args.device)
    except (MemoryError, RuntimeError) as exc:
        what = allocation_failure(exc)
        if what is None:
            raise
        where = f" on {args.device}" if args.device else ""
        if args.ckpt:
            raise ValueError(f"{args.ckpt}: the model's render size {cfg.render.size} px: {what}{where}") from None
        raise ValueError(f"--size {cfg.render.size}: {what} for renders of {cfg.render.size} px{where}; "
                         f"try a smaller --size (default {SCORE_SIZE})") from None
    said = vars(args).setdefault("_cache_warnings", set())
    for w in caught:
        if not issubclass(w.category, CacheWarning):  # not ours: shown as it would have been
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno, source=w.source)
        elif str(w.message) not in said:
            said.add(str(w.message))
            print(f"lit3d-score: warning: {w.message}; the score is computed but not cached (--no-cache skips "
                  "the cache, LIT3D_CACHE=DIR moves it)", file=sys.stderr, flush=True)
    seconds = time.perf_counter() - t0
    prediction = None
    if predictor is not None and args.ckpt:
        out = predictor.predict(table.features)
        prediction = {"score": out.pop("score"), "source": {"model": str(args.ckpt), **out}}
    elif predictor is not None and not predictor.missing(table.features):  # the shipped model
        out = predictor.predict(table.features)
        name = f"{out['model']} from {args.model}" if args.model else f"shipped {out['model']}"
        prediction = {"score": out.pop("score"), "source": {**out, "model": name}}
    return table, seconds, prediction


def _shipped_unusable(model, table) -> str:
    """The note for a pair the shipped model cannot score (it lacks the model's features)."""
    missing = model.missing(table.features)
    return (f"the shipped quality model '{model.name}' scores coloured point-cloud pairs; this pair lacks "
            f"{len(missing)} of its features (e.g. {missing[0]}): unlearned score")


def _doc(ref, dist, table, seconds: float, prediction: dict | None) -> dict:
    """One pair's JSON document (the ``--json`` output of a single pair, less ``config``)."""
    doc = {"ref": str(ref), "dist": str(dist), "overall_score": table.overall_score(), "cached": table.cached,
           "seconds": seconds, "features": table.features}
    if prediction is not None:
        doc.update(predicted_score=prediction["score"], score_source=prediction["source"])
    return doc


def _inputs(args) -> list[Path]:
    """The files this run reads: no output may replace one."""
    return [Path(p) for p in (args.ref, args.dist, args.ckpt) if p]


def _model_features(args, cli_cfg):
    """Load ``--ckpt`` and the feature configuration it was trained with.

    Returns ``(predictor, cfg, notes)``: ``cfg`` replaces the command line's ``--size``/``--styles``
    (``notes`` says so where they differ). Raises ``ValueError`` (one line) for a checkpoint that is
    not a quality model or whose features the renderer does not compute.
    """
    from lit3d.quality.predict import load_predictor

    predictor = load_predictor(args.ckpt)
    if predictor.feature_fn:
        raise ValueError(f"{args.ckpt}: the model was trained on features of data.feature_tables.fn="
                         f"{predictor.feature_fn}, not the renderer's feature table lit3d-score computes")
    if predictor.feature_options is None:
        return predictor, cli_cfg, ["the checkpoint does not record its feature options; features computed "
                                    "with --size/--styles, which may differ from training"]
    cfg = predictor.feature_config()
    notes = []
    if args.size is not None and args.size != cfg.render.size:
        notes.append(f"--size {args.size} ignored: the model was trained on {cfg.render.size} px renders")
    if args.styles is not None and list(cli_cfg.styles) != cfg.resolved_styles():
        notes.append(f"--styles {args.styles} ignored: the model was trained on styles "
                     f"{','.join(cfg.resolved_styles())}")
    return predictor, cfg, notes


if __name__ == "__main__":
    sys.exit(main())
