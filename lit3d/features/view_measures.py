"""The per-view image measures: :func:`crop_box`, :func:`pair_measures` (every measure of a batch of grey image
pairs given as crops), :func:`view_crop`, :func:`chunked_measures` and :func:`view_measures` (every measure of every
MatCap style of one view).

Exact shortcuts (same numbers as the full-canvas definitions): SSIM-family maps,
MSE/RMSE/PSNR/SRE and Canny are computed on the bounding box of the union of all
foreground masks plus a margin wider than every filter support; background
pixels far from the shape have SSIM exactly 1, zero error and no edges, and are
added back analytically. MS-SSIM and FSIM (global statistics) always use the
full canvas; FSIM runs on images averaged down by ``fsim_downsample``.
"""
from __future__ import annotations

from collections.abc import Iterator

import torch

from lit3d.metrics import image as im
from lit3d.render.styles import apply_styles
from lit3d.features.config import CROP_MARGIN, IMAGE_MEASURES, FeatureConfig


def crop_box(masks: torch.Tensor, margin: int) -> tuple[int, int, int, int]:
    """(y0, y1, x0, x1) of the union of ``masks (N, 1, H, W)`` grown by ``margin`` (clipped)."""
    h, w = masks.shape[-2:]
    any_fg = masks.flatten(0, 1).any(0)
    if not bool(any_fg.any()):
        return 0, min(h, 1 + 2 * margin), 0, min(w, 1 + 2 * margin)
    rows = any_fg.any(1).nonzero().squeeze(1)
    cols = any_fg.any(0).nonzero().squeeze(1)
    return (max(int(rows[0]) - margin, 0), min(int(rows[-1]) + margin + 1, h),
            max(int(cols[0]) - margin, 0), min(int(cols[-1]) + margin + 1, w))


def pair_measures(a: torch.Tensor, b: torch.Tensor, mask_a: torch.Tensor, mask_b: torch.Tensor,
                  crop: tuple[int, int, int, int], measures=IMAGE_MEASURES,
                  fsim_downsample: int = 2) -> dict[str, torch.Tensor]:
    """Every image measure for a batch of grey image pairs given as crops of larger canvases.

    Args:
        a, b: ``(N, 1, h, w) float32`` in ``[0, 1]``: the window at ``(y0, x0)`` of
            ``H x W`` canvases that are 0 (black background) outside it.
        mask_a, mask_b: ``(N, 1, h, w)`` or ``(1, 1, h, w)`` (shared by the batch) bool
            foreground, inside the window; each mask
            must be at least :data:`CROP_MARGIN` pixels from a window side that is not a
            canvas side (the SSIM, error and Canny values are then exactly those of the
            full canvases).
        crop: ``(y0, x0, H, W)``.
        measures: subset of :data:`IMAGE_MEASURES`.
        fsim_downsample: FSIM resolution factor (see :func:`lit3d.metrics.image.fsim`,
            whose ``crop`` form is an approximation of the full-canvas FSIM).

    Returns:
        ``{measure: (N,) float32}``.
    """
    want = set(measures)
    out: dict[str, torch.Tensor] = {}
    y0, x0, hh, ww = (int(v) for v in crop)
    total = float(hh * ww)
    outside = total - float(a.shape[-1] * a.shape[-2])
    need_map = want & {"mask_ssim", "mask_ssim_window", "mask_ssim_negative", "mask_ssim_merge", "ssim", "ms_ssim"}
    cs0 = None
    if need_map:
        lum, cs = im.ssim_parts(a, b, 11, 1.5, 1.0, 0.01, 0.03, "symmetric")
        smap = lum.mul_(cs)
        ms = im.mask_ssim_all(a, b, mask_a, mask_b, smap=smap)
        ms["ssim"] = (smap.flatten(1).sum(1) + outside) / total
        cs0 = (cs.flatten(1).sum(1) + outside) / total
        out.update({k: v for k, v in ms.items() if k in want})
        del lum, cs, smap
    if "ms_ssim" in want:
        out["ms_ssim"] = im.ms_ssim(a, b, padding="symmetric", cs0=cs0, crop=crop)
    if "fsim" in want:
        out["fsim"] = im.fsim(a, b, downsample=fsim_downsample, crop=crop)
    if want & {"mse", "rmse", "psnr", "sre"}:
        err = ((a - b) ** 2).flatten(1).sum(1) / total
        mu2 = (a.flatten(1).sum(1) / total) ** 2
        vals = {"mse": err, "rmse": err.sqrt(),
                "psnr": (10.0 * torch.log10(1.0 / err.clamp_min(1e-30))).clamp(max=im.PSNR_MAX_DB),
                "sre": (10.0 * torch.log10(mu2.clamp_min(1e-30) / err.clamp_min(1e-30))).clamp(
                    -im.PSNR_MAX_DB, im.PSNR_MAX_DB)}
        out.update({k: v for k, v in vals.items() if k in want})
    if "canny" in want:
        e = im.canny_edges(torch.cat([a, b]))
        ea, eb = e.chunk(2)
        out["canny"] = (ea ^ eb).float().flatten(1).sum(1) / total
    return out


def view_crop(ga, gb, v: int) -> tuple[tuple[slice, ...], tuple[int, int, int, int]]:
    """``(sl, crop)`` for view ``v`` of two G-buffers: ``sl`` indexes ``(1, C, h, w)`` out of their
    ``(V, C, H, W)`` maps (the union of both masks + :data:`CROP_MARGIN`), ``crop`` is the
    ``(y0, x0, H, W)`` that :func:`pair_measures` takes."""
    hh, ww = ga.mask.shape[-2:]
    y0, y1, x0, x1 = crop_box(torch.cat([ga.mask[v:v + 1], gb.mask[v:v + 1]]), CROP_MARGIN)
    return (slice(v, v + 1), slice(None), slice(y0, y1), slice(x0, x1)), (y0, x0, hh, ww)


def chunked_measures(ia: torch.Tensor, ib: torch.Tensor, ma: torch.Tensor, mb: torch.Tensor,
                     crop: tuple[int, int, int, int],
                     cfg: FeatureConfig) -> Iterator[tuple[int, int, dict[str, torch.Tensor]]]:
    """:func:`pair_measures` of the style images ``ia, ib (S, 1, h, w)`` (masks ``(1, 1, h, w)``)
    ``cfg.chunk`` styles at a time (0: all at once): yields ``(i, j, {measure: (j - i,) float32
    cpu})`` for styles ``i:j``, in order."""
    n = ia.shape[0]
    step = cfg.chunk if cfg.chunk > 0 else n
    for i in range(0, n, step):
        j = min(i + step, n)
        res = pair_measures(ia[i:j], ib[i:j], ma, mb, crop, cfg.measures, cfg.fsim_downsample)
        yield i, j, {k: t.float().cpu() for k, t in res.items()}


def view_measures(ga, gb, v: int, names: list[str], cfg: FeatureConfig) -> dict[str, torch.Tensor]:
    """Every measure of every style for view ``v`` of two G-buffers: ``{measure: (S,) float32 cpu}``.

    The styles are shaded on the view's crop only (:func:`view_crop`).
    """
    sl, crop = view_crop(ga, gb, v)
    ma, mb = ga.mask[sl], gb.mask[sl]
    ia = apply_styles(ga.normals[sl], ma, names, grey=True)[:, 0]  # (S, 1, h, w)
    ib = apply_styles(gb.normals[sl], mb, names, grey=True)[:, 0]
    out: dict[str, list[torch.Tensor]] = {}
    for _, _, res in chunked_measures(ia, ib, ma, mb, crop, cfg):
        for k, t in res.items():
            out.setdefault(k, []).append(t)
    return {k: torch.cat(t) for k, t in out.items()}
