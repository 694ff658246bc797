"""Feature table of a point-cloud pair, rendered as points (no meshing).

Same table as :func:`lit3d.features.table.feature_table` for meshes — every image
measure of every MatCap style, shading and view, names ``measure/style/shading`` — from
the native splat renderer (:mod:`lit3d.render.splat`), plus:

- colour styles (:mod:`lit3d.render.colour_styles`) when both clouds carry colour:
  ``albedo_luma``, ``lit_luma`` and ``matcap_luma`` get every image measure (they are grey
  images); ``albedo_rgb``, ``lit_rgb`` and ``matcap_rgb`` get the SSIM family and MSE/RMSE/PSNR
  on RGB (:data:`RGB_MEASURES`; SSIM maps averaged over the channels, PSNR from the mean
  channel MSE) and the colour measures of ``cfg.colour_measures``: CIEDE2000 inside the masks
  (every RGB colour style) and piq's FSIMc, VIF, GMSD, HaarPSI, MDSI, VSI (:data:`PIQ_STYLES`,
  first shading, half size; :func:`_colour_measures`);
- the point-cloud baselines of :mod:`lit3d.metrics.pointcloud` (``d1_psnr``,
  ``d2_psnr``, ``y_psnr``, their MSEs, ``hausdorff``, ``chamfer``) in the reference's
  normalised frame (longest bounding-box side 1), when ``mesh_measures`` is on, and the
  field's metrics of ``cfg.point_measures`` in the same frame: PointSSIM
  (:mod:`lit3d.metrics.pointssim`, ``pointssim_{geometry,normal,curvature,colour}``) and, for
  coloured clouds, PCQM (:mod:`lit3d.metrics.pcqm`, ``pcqm`` and ``pcqm_<feature>``).

Both clouds are placed in the reference's frame. Local frames (PCA normals, spacing)
of recently seen clouds are kept in memory, so a dataset with one reference computes
the reference's once (:func:`cached_frames`, safe to call from several threads).

The configuration, cache, worker threads and image measures are those of the mesh table,
from :mod:`lit3d.features.view_measures` (this module does not import :mod:`lit3d.features.table`,
which imports it to dispatch point-cloud pairs here).
"""
from __future__ import annotations

import threading
from collections import OrderedDict
from concurrent.futures import Future

import numpy as np
import torch

from lit3d.features.cache import cache_path, read_cached_table, write_cached_table
from lit3d.features.config import FeatureConfig, FeatureTable, content_key
from lit3d.features.view_measures import chunked_measures, pair_measures, view_crop
from lit3d.features.workers import view_worker_count, view_workers
from lit3d.metrics.image import PSNR_MAX_DB
from lit3d.metrics.image.colour_measures import PIQ_MIN_SIZE, ciede2000, piq_measures
from lit3d.metrics.pcqm import pcqm
from lit3d.metrics.pointssim import pointssim
from lit3d.metrics.pointcloud import kd_tree, pointcloud_baselines
from lit3d.render.colour_styles import apply_colour_styles
from lit3d.render.point_clouds import PointShape, load_points, local_frames
from lit3d.render.splat import point_frame, render_point_gbuffers
from lit3d.render.styles import apply_styles

POINT_PATH_VERSION = 3
RGB_MEASURES = ("mask_ssim", "mask_ssim_window", "mask_ssim_negative", "mask_ssim_merge", "ssim", "mse", "rmse",
                "psnr")
GREY_COLOUR_STYLES = ("albedo_luma", "lit_luma", "matcap_luma")
ALBEDO_STYLES = ("albedo_luma", "albedo_rgb")  # unlit: independent of the normals
RGB_COLOUR_STYLES = ("albedo_rgb", "lit_rgb", "matcap_rgb")
PIQ_STYLES = ("matcap_rgb",)  # the colour style piq's measures see: the colours under the MatCap's studio light
_FRAMES: OrderedDict[str, dict[str, np.ndarray]] = OrderedDict()  # key -> frames, least recent first
_FRAMES_KEEP = 4
_FRAMES_LOCK = threading.Lock()  # guards _FRAMES and _FRAMES_PENDING
_FRAMES_PENDING: dict[str, Future] = {}  # key -> the frames being computed by another thread


def cached_frames(shape: PointShape, key: str, workers: int = -1) -> dict[str, np.ndarray]:
    """:func:`lit3d.render.point_clouds.local_frames` of ``shape`` (its KD-tree query on ``workers`` threads; the
    frames do not depend on them), memoised for the last few clouds.

    Thread-safe: the look-up, the insertion and the eviction of :data:`_FRAMES` run under
    :data:`_FRAMES_LOCK`; the frames themselves are computed outside it (two clouds' frames
    still run side by side), and a thread asking for a cloud that another thread is computing
    waits for that result instead of computing it again.
    """
    with _FRAMES_LOCK:
        if key in _FRAMES:
            _FRAMES.move_to_end(key)
            return _FRAMES[key]
        pending = _FRAMES_PENDING.get(key)
        owner = pending is None
        if owner:
            pending = _FRAMES_PENDING[key] = Future()
    if not owner:
        return pending.result()
    try:
        lf = local_frames(shape.points, workers=workers)
    except BaseException as exc:
        with _FRAMES_LOCK:
            del _FRAMES_PENDING[key]
        pending.set_exception(exc)
        raise
    with _FRAMES_LOCK:
        _FRAMES[key] = lf
        while len(_FRAMES) > _FRAMES_KEEP:
            _FRAMES.popitem(last=False)
        del _FRAMES_PENDING[key]
    pending.set_result(lf)
    return lf


def _rgb_measures(a: torch.Tensor, b: torch.Tensor, ma, mb, crop, measures) -> dict[str, torch.Tensor]:
    """RGB pairs ``(N, 3, h, w)`` -> ``{measure: (N,)}`` for ``measures`` within :data:`RGB_MEASURES`."""
    want = [m for m in measures if m in RGB_MEASURES]
    if not want:
        return {}
    n = a.shape[0]
    grey = [m for m in want if m not in ("rmse", "psnr")] + (["mse"] if {"rmse", "psnr"} & set(want) else [])
    res = pair_measures(a.reshape(n * 3, 1, *a.shape[-2:]), b.reshape(n * 3, 1, *b.shape[-2:]), ma, mb, crop,
                        tuple(dict.fromkeys(grey)))
    out = {k: v.view(n, 3).mean(1) for k, v in res.items()}
    if "mse" in out:
        out["rmse"] = out["mse"].sqrt()
        out["psnr"] = (10.0 * torch.log10(1.0 / out["mse"].clamp_min(1e-30))).clamp(max=PSNR_MAX_DB)
    return {k: v for k, v in out.items() if k in want}


def _colour_measures(a: torch.Tensor, b: torch.Tensor, ma, mb, crop, measures, styles: list[str], first: bool,
                     downsample: int) -> dict[tuple[str, str], torch.Tensor]:
    """``{(measure, style): (1,)}`` of the RGB colour styles ``a, b (S, 3, h, w)`` of one view (its crop, masks
    ``(1, 1, h, w)``) for ``measures`` within :data:`lit3d.features.config.COLOUR_MEASURES`: CIEDE2000 inside
    the masks for every style; piq's measures (``fsimc``: piq's chromatic FSIM) for :data:`PIQ_STYLES` under the
    first shading only (``first``), on the full canvas averaged down by ``downsample`` (piq's measures pool
    global statistics: 60 full-size images a pair would cost about 20 s on two cores), less where that would
    leave fewer pixels than a measure needs (:data:`PIQ_MIN_SIZE`); a canvas too small for a measure has none."""
    out = {}
    if "ciede2000" in measures:
        de = ciede2000(a, b, ma, mb)
        out.update({("ciede2000", s): de[j:j + 1] for j, s in enumerate(styles)})
    want = {m: "fsim" if m == "fsimc" else m for m in measures if m != "ciede2000"}
    rows = [j for j, s in enumerate(styles) if s in PIQ_STYLES]
    if want and first and rows:
        side = min(crop[2:])  # the full canvas: piq_measures pads the crop back to it
        downsample = max(1, min(downsample, side // max(PIQ_MIN_SIZE[m] for m in want.values())))
        # a canvas smaller than a measure's smallest image (VIF: 41 px) has no such feature
        want = {name: m for name, m in want.items() if side // downsample >= PIQ_MIN_SIZE[m]}
        res = piq_measures(a[rows], b[rows], tuple(want.values()), crop=crop, downsample=downsample)
        for name, m in want.items():
            out.update({(name, styles[j]): res[m][i:i + 1] for i, j in enumerate(rows)})
    return out


def _point_view_measures(ga, gb, v: int, names: list[str], cfg: FeatureConfig, colour: bool,
                   albedo: bool = True) -> dict[tuple[str, str], torch.Tensor]:
    """``{(measure, style): (1,) float32}`` for view ``v`` of two point G-buffers (crop of the union of masks).

    ``albedo=False`` skips the unlit colour styles (they do not depend on the shading's normals,
    so one shading's values serve both)."""
    sl, crop = view_crop(ga, gb, v)
    ma, mb = ga.mask[sl], gb.mask[sl]
    ia = apply_styles(ga.normals[sl], ma, names, grey=True)[:, 0]  # (S, 1, h, w)
    ib = apply_styles(gb.normals[sl], mb, names, grey=True)[:, 0]
    styles = list(names)
    out: dict[tuple[str, str], torch.Tensor] = {}
    if colour:
        ca = apply_colour_styles(ga.colour[sl], ga.normals[sl], ma)
        cb = apply_colour_styles(gb.colour[sl], gb.normals[sl], mb)
        grey = [s for s in GREY_COLOUR_STYLES if albedo or s not in ALBEDO_STYLES]
        rgb_styles = [s for s in RGB_COLOUR_STYLES if albedo or s not in ALBEDO_STYLES]
        ia = torch.cat([ia] + [ca[s] for s in grey])
        ib = torch.cat([ib] + [cb[s] for s in grey])
        styles += grey
        stack_a, stack_b = torch.cat([ca[s] for s in rgb_styles]), torch.cat([cb[s] for s in rgb_styles])
        rgb = _rgb_measures(stack_a, stack_b, ma, mb, crop, cfg.measures)
        for k, t in rgb.items():
            for j, s in enumerate(rgb_styles):
                out[(k, s)] = t[j:j + 1].float().cpu()
        if cfg.colour_measures:
            found = _colour_measures(stack_a, stack_b, ma, mb, crop, cfg.colour_measures, rgb_styles, albedo,
                                     cfg.fsim_downsample)
            out.update({k: t.float().cpu() for k, t in found.items()})
    for i, j, res in chunked_measures(ia, ib, ma, mb, crop, cfg):
        for k, t in res.items():
            for o, s in enumerate(styles[i:j]):
                out[(k, s)] = t[o:o + 1]
    return out


def point_feature_table(ref, dist, cfg: FeatureConfig | None = None, *, cache_dir=None, device=None) -> FeatureTable:
    """Compute (or load from cache) the feature table of a point-cloud pair (see the module doc).

    Args:
        ref, dist: anything :func:`lit3d.render.point_clouds.load_points` accepts.
        cfg: feature configuration (render size, styles, measures, shadings, workers).
        cache_dir: folder of cached JSON tables (None: no caching).
        device: torch device for the measures (default CPU).

    Order of work (on the worker threads; every value is that of computing the parts one after the
    other): each cloud's local frames then its render, as one task per cloud; without a cache folder
    the reference's task starts while the distorted cloud is still being parsed (parsing holds the
    GIL, the KD-tree query does not). PointSSIM and PCQM need only the points: they start with the
    renders, on one KD-tree per cloud that both use (:func:`_point_metrics`). The D1/D2/Y-PSNR
    baselines need the smooth normals, the image measures the renders: they start when those are there.
    With several workers each of these tasks runs on one thread (the workers already fill the cores;
    more threads per task only contend for them); with one, the KD-tree queries, PointSSIM and PCQM
    use every core. Neither changes a value.
    """
    cfg = cfg or FeatureConfig()
    inner = 1 if view_worker_count(cfg.workers, device) > 1 else -1  # threads of one task's own work
    with view_workers(cfg.workers, device) as submit:  # one intra-op thread, whole views per worker
        pa = load_points(ref)  # one after the other: parsing holds the GIL
        ha = pa.content_hash()
        frame = point_frame(pa.points)
        # no cache to look up: nothing can make the reference's frames and render wasted work
        task_a = submit(_frames_and_render, pa, ha, cfg, frame, inner) if cache_dir is None else None
        pb = load_points(dist)
        hb = pb.content_hash()
        key = content_key(f"points{POINT_PATH_VERSION}:{ha}", f"points{POINT_PATH_VERSION}:{hb}", cfg)
        path = cache_path(cache_dir, key)
        cached = read_cached_table(path, key)
        if cached is not None:
            return cached
        names = cfg.resolved_styles()
        colour = pa.colours is not None and pb.colours is not None
        if task_a is None:
            task_a = submit(_frames_and_render, pa, ha, cfg, frame, inner)
        task_b = submit(_frames_and_render, pb, hb, cfg, frame, inner)
        metrics = submit(_point_metrics, pa, pb, frame, colour, cfg, inner) if cfg.point_measures else None
        (fa, ga), (fb, gb) = task_a.result(), task_b.result()
        base = submit(_baselines, pa, pb, fa, fb, frame, colour, inner) if cfg.mesh_measures else None
        pending = []
        for i, shading in enumerate(cfg.render.shadings):
            sa, sb = ga[shading], gb[shading]
            if device is not None:
                sa, sb = sa.to(device), sb.to(device)
            for v in range(sa.mask.shape[0]):
                pending.append((shading, submit(_point_view_measures, sa, sb, v, names, cfg, colour, i == 0)))
        per: dict[str, list[float]] = {}
        for shading, res in pending:
            for (k, s), t in res.result().items():
                per.setdefault(f"{k}/{s}/{shading}", []).append(float(t[0]))
        first = cfg.render.shadings[0]
        for name in [n for n in per if n.split("/")[1] in ALBEDO_STYLES and n.endswith(f"/{first}")]:
            for shading in cfg.render.shadings[1:]:  # unlit colour: the same images under every shading
                per[name[: -len(first)] + shading] = per[name]
        baselines = base.result() if base is not None else {}
        baselines.update(metrics.result() if metrics is not None else {})
    feats = {k: float(np.mean(v)) for k, v in per.items()}
    feats.update(baselines)
    write_cached_table(path, key, cfg, feats)
    return FeatureTable(feats, key, cached=False, per_view={k: np.asarray(v) for k, v in per.items()})


def _frames_and_render(shape: PointShape, key: str, cfg: FeatureConfig, frame, workers: int = -1):
    """``(local frames, {shading: PointGBuffer})`` of one cloud: its (memoised) frames, then its splats."""
    lf = cached_frames(shape, key, workers)
    return lf, render_point_gbuffers(shape, cfg.render, frame=frame, frames=lf)


def _normalised(pa: PointShape, pb: PointShape, frame, colour: bool):
    """Both clouds' positions in the reference's normalised frame and their colours (None without colour)."""
    c, s = frame
    return (pa.points - c) * s, (pb.points - c) * s, *((pa.colours, pb.colours) if colour else (None, None))


def _baselines(pa: PointShape, pb: PointShape, fa, fb, frame, colour: bool, workers: int = -1) -> dict[str, float]:
    """The point-cloud baselines of the pair in the reference's normalised frame: D1/D2/Y-PSNR, Hausdorff and
    Chamfer (the table's ``mesh_measures``; D2 with the clouds' smooth normals)."""
    a, b, ca, cb = _normalised(pa, pb, frame, colour)
    return pointcloud_baselines(a, b, fa["smooth"], fb["smooth"], ca, cb, workers=workers)


def _point_metrics(pa: PointShape, pb: PointShape, frame, colour: bool, cfg: FeatureConfig,
                   workers: int = -1) -> dict[str, float]:
    """The field's metrics of ``cfg.point_measures`` in the reference's normalised frame: PointSSIM and PCQM
    (PCQM needs colour), on one KD-tree per cloud (:func:`lit3d.metrics.pointcloud.kd_tree`) that both search
    (the scores are those of each metric building its own)."""
    a, b, ca, cb = _normalised(pa, pb, frame, colour)
    want_ssim, want_pcqm = "pointssim" in cfg.point_measures, "pcqm" in cfg.point_measures and colour
    if not (want_ssim or want_pcqm):
        return {}
    trees = (kd_tree(a), kd_tree(b)) if want_ssim and want_pcqm else None
    out = pointssim(a, b, ca, cb, trees=trees, workers=workers) if want_ssim else {}
    if want_pcqm:
        out.update(pcqm(a, b, ca, cb, trees=trees, workers=workers))
    return out
