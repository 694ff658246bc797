"""Canny edges and the Canny-edge difference against scikit-image's Canny (an independent implementation)."""
from __future__ import annotations

from itertools import pairwise

import numpy as np
import pytest
import torch
from scipy import ndimage

from lit3d.metrics import image as im

skf = pytest.importorskip("skimage.feature")

NEAR_BOUND = 0.95  # fraction of edge pixels within 1 px of the other detector's / the true border


def _ours(img: np.ndarray) -> np.ndarray:
    return im.canny_edges(torch.from_numpy(img).float()[None, None])[0, 0].numpy()


def _skimage(img: np.ndarray) -> np.ndarray:
    # same smoothing scale (sigma 1) and thresholds in the same unnormalised-Sobel units
    return skf.canny(img, sigma=1.0, low_threshold=0.1, high_threshold=0.2)


def _near(a: np.ndarray, b: np.ndarray, r: int = 1) -> float:
    """Fraction of ``a``'s pixels within chessboard distance ``r`` of a pixel of ``b``."""
    grown = ndimage.binary_dilation(b, np.ones((2 * r + 1, 2 * r + 1), bool))
    return float((a & grown).sum()) / max(int(a.sum()), 1)


def _square(n=64, lo=20, hi=44, value=0.8, shift=(0, 0)) -> np.ndarray:
    img = np.zeros((n, n))
    img[lo + shift[0]:hi + shift[0], lo + shift[1]:hi + shift[1]] = value
    return img


@pytest.mark.parametrize("img", [_square(), _square(value=0.3), _square(shift=(3, -5)),
                                 (((np.mgrid[:96, :96] - np.array([48, 45])[:, None, None]) ** 2).sum(0) < 25**2) * 0.7],
                         ids=["square", "faint-square", "shifted-square", "disk"])
def test_edges_lie_on_the_shape_border_and_agree_with_skimage(img):
    ours, ref = _ours(img), _skimage(img)
    shape = img > 0
    border = shape & ~ndimage.binary_erosion(shape)  # inner ring of the shape
    assert ours.sum() > 0.8 * border.sum()
    assert _near(ours, border) >= NEAR_BOUND  # our edges sit on the border (within 1 px)
    assert _near(border, ours) >= NEAR_BOUND  # and cover all of it
    assert _near(ours, ref) >= NEAR_BOUND  # precision against scikit-image
    assert _near(ref, ours) >= NEAR_BOUND  # recall against scikit-image
    assert not ours[:4].any() and not ours[:, :4].any()  # nothing far from the shape


def test_flat_images_have_no_edges():
    for v in (0.0, 0.5, 1.0):
        assert not _ours(np.full((32, 32), v)).any()


def test_canny_diff_grows_with_noise_like_skimage():
    base = ndimage.gaussian_filter(_square(96, 25, 70), 1.0)
    ours, ref = [], []
    for sigma in (0.0, 0.02, 0.1, 0.2):
        o, r = [], []
        for seed in range(4):
            noisy = np.clip(base + sigma * np.random.default_rng(seed).standard_normal(base.shape), 0, 1)
            a, b = (torch.from_numpy(x).float()[None, None] for x in (base, noisy))
            o.append(float(im.canny_diff(a, b)))
            r.append(float((_skimage(base) ^ _skimage(noisy)).mean()))
        ours.append(np.mean(o))
        ref.append(np.mean(r))
    assert ours[0] == 0.0 and ref[0] == 0.0
    assert all(x < y for x, y in pairwise(ours)), ours  # grows with distortion
    assert all(x < y for x, y in pairwise(ref)), ref  # (the reference does too)
    for o, r in zip(ours[1:], ref[1:]):
        assert 0.5 < o / r < 2.0, (ours, ref)  # same size as scikit-image's edge difference


def test_canny_diff_of_a_moved_square_grows_like_skimage():
    a = torch.from_numpy(_square()).float()[None, None]
    diffs = [float(im.canny_diff(a, torch.from_numpy(_square(shift=(0, k))).float()[None, None])) for k in range(4)]
    assert diffs[0] == 0.0 and diffs[1] > 0.0
    assert all(x <= y for x, y in pairwise(diffs)), diffs
    ref = float((_skimage(_square()) ^ _skimage(_square(shift=(0, 3)))).mean())
    assert 0.5 < diffs[-1] / ref < 2.0, (diffs, ref)
