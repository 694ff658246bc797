"""Image measures against independent references (scikit-image, kornia, torchmetrics, hand values)."""
from __future__ import annotations

import numpy as np
import pytest
import torch
from scipy import ndimage

from lit3d.metrics import image as im

skm = pytest.importorskip("skimage.metrics")


def _smooth_pair(h=48, w=40, seed=0, n=3):
    g = np.random.default_rng(seed)
    a = ndimage.gaussian_filter(g.random((n, h, w)), (0, 2, 2))
    a = (a - a.min()) / (a.max() - a.min())
    b = np.clip(a + 0.08 * g.standard_normal(a.shape), 0, 1)
    return torch.from_numpy(a).float()[:, None], torch.from_numpy(b).float()[:, None]


def _sk_map(a, b):
    _, s = skm.structural_similarity(a.double().numpy(), b.double().numpy(), gaussian_weights=True, sigma=1.5,
                                     use_sample_covariance=False, data_range=1.0, full=True)
    return s


def test_ssim_map_matches_skimage_and_mask_ssim_full_masks_is_its_mean():
    a, b = _smooth_pair()
    smap = im.ssim_map(a, b)
    full = torch.ones_like(a, dtype=torch.bool)
    ms = im.mask_ssim(a, b, full, full)
    for i in range(a.shape[0]):
        ref = _sk_map(a[i, 0], b[i, 0])
        assert np.abs(smap[i, 0].numpy() - ref).max() < 1e-4
        assert abs(float(ms[i]) - ref.mean()) < 1e-4
        assert abs(float(im.ssim(a, b)[i]) - ref.mean()) < 1e-4


def test_ssim_map_reflect_padding_matches_kornia():
    kornia = pytest.importorskip("kornia")
    a, b = _smooth_pair(seed=1)
    ours = im.ssim_map(a, b, padding="reflect")
    ref = kornia.metrics.ssim(a, b, 11)
    assert (ours - ref).abs().max() < 1e-4


def test_mask_ssim_variants_hand_computed():
    h = w = 5
    c = torch.full((1, 1, h, w), 0.5)
    c[0, 0, 0, 0] = 1.0
    ma = torch.ones(1, 1, h, w, dtype=torch.bool)
    ma[..., :, 4] = False  # column 4 background in A
    mb = torch.ones(1, 1, h, w, dtype=torch.bool)
    mb[..., 4, :] = False  # row 4 background in B
    x = torch.zeros(1, 1, h, w)
    # both: 4x4 block (16 px, sum 15*0.5 + 1 = 8.5); xor: 8 px; 3x3-interior of the block: 4 px of 0.5
    got = {v: float(im.mask_ssim(x, x, ma, mb, v, smap=c)) for v in im.MASK_SSIM_VARIANTS}
    assert got["plain"] == pytest.approx(8.5 / 16)
    assert got["window"] == pytest.approx(0.5)
    assert got["negative"] == pytest.approx((8.5 - 8) / (16 + 8))
    assert got["merge"] == pytest.approx(0.5 * (8.5 / 16 + 0.5 / 24))
    allv = im.mask_ssim_all(x, x, ma, mb, smap=c)
    assert float(allv["mask_ssim_merge"]) == pytest.approx(got["merge"])
    assert float(allv["mask_ssim_window"]) == pytest.approx(got["window"])
    # symmetric in (A, B)
    assert float(im.mask_ssim(x, x, mb, ma, "negative", smap=c)) == pytest.approx(got["negative"])


def test_mask_ssim_empty_and_disjoint_masks_are_defined():
    a, b = _smooth_pair(h=16, w=16, n=1)
    empty = torch.zeros_like(a, dtype=torch.bool)
    left = torch.zeros_like(empty)
    left[..., :8] = True
    for v in im.MASK_SSIM_VARIANTS:
        assert float(im.mask_ssim(a, b, empty, empty, v)) == 1.0
    assert float(im.mask_ssim(a, b, left, ~left, "plain")) == 0.0
    assert float(im.mask_ssim(a, b, left, ~left, "window")) == 0.0
    assert float(im.mask_ssim(a, b, left, ~left, "negative")) == -1.0
    assert float(im.mask_ssim(a, b, left, ~left, "merge")) == -0.5
    assert float(im.mask_ssim(a, b, left, empty, "plain")) == 0.0


def test_ms_ssim_matches_torchmetrics_and_box_shortcut_is_exact():
    tmf = pytest.importorskip("torchmetrics.functional.image")
    a, b = _smooth_pair(h=192, w=192, n=2, seed=3)
    ref = tmf.multiscale_structural_similarity_index_measure(a, b, data_range=1.0, reduction="none")
    ours = im.ms_ssim(a, b)
    assert (ours - ref).abs().max() < 5e-4  # float32 conv vs matrix-product filtering at 12 px scales
    # shapes on a black canvas: box shortcut == full computation
    canvas_a = torch.zeros(2, 1, 256, 256)
    canvas_b = torch.zeros(2, 1, 256, 256)
    canvas_a[..., 40:232, 30:222] = a
    canvas_b[..., 40:232, 30:222] = b
    full = im.ms_ssim(canvas_a, canvas_b, padding="symmetric")
    boxed = im.ms_ssim(canvas_a, canvas_b, padding="symmetric", box=(40, 232, 30, 222))
    assert (full - boxed).abs().max() < 1e-5


def test_ms_ssim_small_images_no_nan():
    a, b = _smooth_pair(h=40, w=40, n=2)
    v = im.ms_ssim(a, b)
    assert torch.isfinite(v).all() and (v <= 1).all()
    assert torch.allclose(im.ms_ssim(a, a), torch.ones(2), atol=1e-5)


def test_fsim_properties():
    a, b = _smooth_pair(h=64, w=64, n=2, seed=4)
    assert torch.allclose(im.fsim(a, a), torch.ones(2), atol=1e-5)
    worse = torch.clamp(a + 0.3 * torch.randn_like(a), 0, 1)
    f1, f2 = im.fsim(a, b), im.fsim(a, worse)
    assert ((f1 < 1) & (f2 < f1)).all()
    flat = torch.zeros(1, 1, 32, 32)
    assert float(im.fsim(flat, flat)) == 1.0


def test_pixel_errors():
    a = torch.zeros(2, 1, 4, 4)
    b = torch.zeros(2, 1, 4, 4)
    b[0, 0, 0, 0] = 1.0
    b[1] = 0.5
    assert torch.allclose(im.mse(a, b), torch.tensor([1 / 16, 0.25]))
    assert torch.allclose(im.rmse(a, b), torch.tensor([0.25, 0.5]))
    assert torch.allclose(im.psnr(a, b), torch.tensor([10 * np.log10(16), 10 * np.log10(4)]).float())
    assert float(im.psnr(a, a)[0]) == im.PSNR_MAX_DB
    ref = torch.full((1, 1, 4, 4), 0.5)
    dist = ref + 0.05
    assert float(im.sre(ref, dist)) == pytest.approx(10 * np.log10(0.25 / 0.0025), rel=1e-4)
    assert torch.isfinite(im.sre(a, b)).all()


def test_canny_matches_kornia():
    kornia = pytest.importorskip("kornia")
    g = np.random.default_rng(5)
    img = ndimage.gaussian_filter(g.random((3, 64, 64)), (0, 3, 3))
    img = (img - img.min()) / (img.max() - img.min())
    img[:, 20:40, 10:30] += 0.5
    x = torch.from_numpy(np.clip(img, 0, 1)).float()[:, None]
    ours = im.canny_edges(x)
    ref = kornia.filters.canny(x)[1] > 0.5
    assert ref.sum() > 50
    assert (ours ^ ref).float().mean() < 1e-3
    assert float(im.canny_diff(x, x).max()) == 0.0
    assert float(im.canny_diff(x, x.flip(-1)).min()) > 0.0
