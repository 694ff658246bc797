"""``lit3d-reconstruct``'s set-up: argument checks, the camera, masks, the models (zoo defaults) and the
``--reference`` scorer (:mod:`lit3d.cli.reconstruct` runs the images)."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

# the zoo models used when no checkpoint is given (lit3d.zoo)
ZOO_COMPLETION = "completion-furniture"
ZOO_CANONICAL = "canonical-people"


def say(msg: str) -> None:
    print(f"lit3d-reconstruct: {msg}", file=sys.stderr, flush=True)


def intrinsics(args, width: int, height: int, label: str):
    from lit3d.reconstruct.backproject import RECGAN_FOV_DEG, Intrinsics

    given = [getattr(args, k) for k in ("fx", "fy", "cx", "cy")]
    if any(v is not None for v in given):
        return Intrinsics(*given).check(width, height, label)
    fov = RECGAN_FOV_DEG if args.fov is None else args.fov  # --fov 0 is refused, never the default
    return Intrinsics.from_fov(fov, width, height).check(width, height, label)


def camera_source(args) -> str:
    """Where the intrinsics came from (written to the JSON: a unit assumed is a unit stated)."""
    from lit3d.reconstruct.backproject import RECGAN_FOV_DEG

    if args.fx is not None:
        return "--fx --fy --cx --cy (pixels)"
    if args.fov is not None:
        return f"--fov {args.fov:g} deg, principal point at the centre"
    return f"default: the 3D-RecGAN++ camera, fov {RECGAN_FOV_DEG:g} deg across width and height, centred"


def check_args(args) -> None:
    from lit3d.reconstruct.depth_io import InputError
    from lit3d.utils.extras import require

    given = [getattr(args, k) for k in ("fx", "fy", "cx", "cy")]
    if any(v is not None for v in given) and not all(v is not None for v in given):
        raise InputError("--fx --fy --cx --cy: give all four intrinsics (or --fov)")
    if args.fov is not None and any(v is not None for v in given):
        raise InputError("--fov and --fx/--fy/--cx/--cy: give one camera, not both")
    if args.fov is not None and not 0 < args.fov < 180:
        raise InputError(f"--fov {args.fov:g}: expected a field of view in (0, 180) degrees")
    if not args.depth_scale > 0 or args.depth_scale != args.depth_scale or args.depth_scale == float("inf"):
        raise InputError(f"--depth-scale {args.depth_scale:g}: expected a positive number of metres per unit")
    if args.body and (args.ckpt or args.canonical or args.reference):
        raise InputError("--body (Anny fit) goes without --ckpt, --canonical and --reference")
    if args.body:
        require("body", "--body")
    if (args.body_init and not args.body) or (args.body_refine_poor and str(args.body_init).lower() == "none"):
        raise InputError("--body-init CKPT: needs --body, and --body-refine-poor N needs a regressor, not none")
    if args.quality_ckpt and not args.reference:
        raise InputError("--quality-ckpt needs --reference (the shape to score against)")
    if not 64 <= args.size <= 2048:
        raise InputError(f"--size {args.size}: expected 64..2048 pixels")
    if args.near is not None and args.far is not None and args.near >= args.far:
        raise InputError(f"--near {args.near} >= --far {args.far}: empty depth range")


def mask_for(args, depth_path: Path, shape):
    """``(mask (H, W) bool, its file)`` for ``depth_path`` (``(None, None)`` without --mask); a
    mask folder is paired by exact stem (:func:`lit3d.reconstruct.depth_io.find_mask`)."""
    from lit3d.reconstruct.depth_io import find_mask, read_mask

    if not args.mask:
        return None, None
    m = find_mask(args.mask, depth_path)
    return read_mask(m, shape), m


class Scorer:
    """``--reference``/``--quality-ckpt``: lit3d-score's rendering-based features of (REF, result)."""

    def __init__(self, args):
        from lit3d.cli.score import _model_features
        from lit3d.features import SCORE_SIZE
        from lit3d.features.table import FeatureConfig
        from lit3d.render.convert import to_mesh

        self.ref = to_mesh(args.reference)
        self.cfg = FeatureConfig.rendered(SCORE_SIZE)
        self.predictor, self.notes = None, []
        if args.quality_ckpt:
            ns = argparse.Namespace(ckpt=args.quality_ckpt, size=None, styles=None)
            self.predictor, self.cfg, self.notes = _model_features(ns, self.cfg)
        self.args = args

    def score(self, mesh) -> dict:
        from lit3d.features.table import feature_table

        table = feature_table(self.ref, mesh, self.cfg, cache_dir=None, device=self.args.device)
        out = {"reference": str(self.args.reference), "overall_score_mean_mask_ssim": table.overall_score(),
               "chamfer": table.features.get("chamfer"), "hausdorff": table.features.get("hausdorff"),
               "notes": list(self.notes)}
        if self.predictor is not None:
            pred = self.predictor.predict(table.features)
            out.update(predicted_score=pred.pop("score"), quality_ckpt=str(self.args.quality_ckpt),
                       score_source=pred)
        return out


def resolve_models(args) -> list[str]:
    """Zoo names (and the defaults: no ``--ckpt`` -> ``completion-furniture``) become files in ``args``.
    Returns the console lines that name each shipped model used (none for checkpoint files given)."""
    from lit3d.zoo import resolve

    wanted = [] if args.body else [("ckpt", "completion", ZOO_COMPLETION)]
    if args.canonical:
        wanted.append(("canonical", "canonical", None))
    lines = []
    for key, what, default in wanted:
        path, label = resolve(getattr(args, key) or default)
        setattr(args, key, str(path))
        if label.startswith("shipped"):
            lines.append(f"{what} model: {label}")
    return lines
