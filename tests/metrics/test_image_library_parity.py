"""Image-metrics helpers against the libraries they use or stand in for (kornia, scipy, scikit-image, torchmetrics),
and the shape of the lit3d.metrics.image package itself."""
from __future__ import annotations

import importlib
import pkgutil
from pathlib import Path

import numpy as np
import pytest
import torch
from scipy import ndimage

from lit3d.metrics import image as im

kornia = pytest.importorskip("kornia")


@pytest.mark.parametrize("window,sigma", [(11, 1.5), (5, 1.0), (7, 0.8)])
def test_gaussian_kernel_is_the_textbook_gaussian(window, sigma):
    x = np.arange(window) - (window - 1) / 2
    g = np.exp(-(x**2) / (2 * sigma**2))
    k = im.gaussian_kernel1d(window, sigma)
    assert k.dtype == torch.float64 and k.shape == (window,)
    assert np.abs(k.numpy() - g / g.sum()).max() < 1e-15


def test_gaussian_kernel1d_is_made_once_and_handed_out_as_copies():
    """Made once per (window, sigma): bit-identical to kornia's, and each call gets its own copy (changing one
    leaves the next intact)."""
    from kornia.filters import get_gaussian_kernel1d

    first = im.gaussian_kernel1d(11, 1.5)
    assert torch.equal(first, get_gaussian_kernel1d(11, 1.5, dtype=torch.float64)[0])
    first.zero_()
    assert torch.equal(im.gaussian_kernel1d(11, 1.5), get_gaussian_kernel1d(11, 1.5, dtype=torch.float64)[0])


@pytest.mark.parametrize("padding,mode", [("symmetric", "reflect"), ("reflect", "mirror"),
                                          ("replicate", "nearest"), ("zeros", "constant")])
def test_separable_filter_matches_scipy_borders(padding, mode):
    x = np.random.default_rng(0).random((2, 150, 37))  # one axis on the banded CPU path, one dense
    taps = im.gaussian_kernel1d(11, 1.5)
    ours = im.separable_filter(torch.from_numpy(x), taps, padding).numpy()
    ref = ndimage.correlate1d(ndimage.correlate1d(x, taps.numpy(), axis=1, mode=mode), taps.numpy(), axis=2, mode=mode)
    assert np.abs(ours - ref).max() < 1e-12


def test_erode3x3_matches_scipy_and_kornia():
    m = torch.from_numpy(np.random.default_rng(1).random((3, 1, 40, 33)) > 0.25)
    m[..., 5:30, 4:25] = True
    ours = im.erode3x3(m)
    ref = ndimage.binary_erosion(m.numpy(), np.ones((1, 1, 3, 3), bool), border_value=0)
    assert np.array_equal(ours.numpy(), ref)
    k = kornia.morphology.erosion(m.float(), torch.ones(3, 3), border_type="constant", border_value=0.0) > 0.5
    assert torch.equal(ours, k)


def test_to_grey_is_bt601_luma():
    rgb = torch.rand(2, 3, 9, 7)
    ref = 0.299 * rgb[:, 0] + 0.587 * rgb[:, 1] + 0.114 * rgb[:, 2]
    assert im.to_grey(rgb).shape == (2, 1, 9, 7)
    assert (im.to_grey(rgb)[:, 0] - ref).abs().max() < 1e-6
    grey = torch.rand(2, 1, 4, 4)
    assert im.to_grey(grey) is grey


def test_pixel_errors_match_skimage_and_torchmetrics():
    skm = pytest.importorskip("skimage.metrics")
    tmf = pytest.importorskip("torchmetrics.functional.image")
    g = np.random.default_rng(2)
    a = g.random((3, 1, 16, 12))
    b = np.clip(a + 0.05 * g.standard_normal(a.shape), 0, 1)
    ta, tb = torch.from_numpy(a).float(), torch.from_numpy(b).float()
    ref_mse = [skm.mean_squared_error(a[i], b[i]) for i in range(3)]
    ref_psnr = [skm.peak_signal_noise_ratio(a[i], b[i], data_range=1.0) for i in range(3)]
    assert np.allclose(im.mse(ta, tb).numpy(), ref_mse, rtol=1e-5)
    assert np.allclose(im.rmse(ta, tb).numpy(), np.sqrt(ref_mse), rtol=1e-5)
    assert np.allclose(im.psnr(ta, tb).numpy(), ref_psnr, rtol=1e-5)
    tm = tmf.peak_signal_noise_ratio(ta, tb, data_range=1.0, reduction="none", dim=(1, 2, 3))
    assert torch.allclose(im.psnr(ta, tb), tm, rtol=1e-5)
    ref_nrmse = [skm.normalized_root_mse(a[i], b[i], normalization="mean") for i in range(3)]
    assert np.allclose(im.sre(ta, tb).numpy(), -20 * np.log10(ref_nrmse), rtol=1e-4)  # SRE = -20 log10 NRMSE_mean


PUBLIC = ("FSIM_CROP_MARGIN", "MASK_SSIM_VARIANTS", "MS_SSIM_WEIGHTS", "PSNR_MAX_DB", "canny_diff", "canny_edges",
          "fsim", "mask_ssim", "mask_ssim_all", "ms_ssim", "mse", "psnr", "rmse", "sre", "ssim", "ssim_map",
          "to_grey", "ssim_parts")  # every name imported from lit3d.metrics.image in lit3d, tests, benchmarks


def test_package_reexports_every_used_name_and_modules_stay_small():
    for name in PUBLIC:
        assert hasattr(im, name), name
    assert set(im.__all__) <= set(dir(im))
    root = Path(im.__file__).parent
    for info in pkgutil.iter_modules([str(root)]):
        importlib.import_module(f"lit3d.metrics.image.{info.name}")
    for path in root.glob("*.py"):
        assert len(path.read_text().splitlines()) < 400, path.name
