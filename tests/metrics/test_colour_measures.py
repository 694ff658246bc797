"""Colour measures (lit3d.metrics.image.colour_measures): CIEDE2000 against scikit-image and Sharma et
al.'s published test pairs, the mask rules, and the piq measures against piq called directly.

piq is a test-only dependency installed by ``scripts/bootstrap.sh`` with ``--no-deps``; its package
``__init__`` imports torchvision, which is not installed, so ``pytest.importorskip("piq")`` would always
skip (the failing ``import piq`` raises ``ModuleNotFoundError``). The piq tests skip only when piq
itself is missing, and the reference functions are loaded here on their own, the way
``tests/metrics/test_fsim_piq.py`` loads ``piq.fsim`` (not through the module under test).
"""
from __future__ import annotations


import numpy as np
import pytest
import torch
from kornia.color import rgb_to_lab
from tests.helpers.piq import piq_functions
from skimage.color import deltaE_ciede2000, rgb2lab

from lit3d.metrics.image.colour_measures import (
    LOWER_IS_BETTER_PIQ,
    PIQ_MEASURES,
    PIQ_MIN_SIZE,
    ciede2000,
    delta_e_ciede2000,
    piq_measures,
)

# Sharma, Wu & Dalal (2005), Table 1: L1, a1, b1, L2, a2, b2, ΔE00 (all 34 pairs; 4 decimals as published).
SHARMA_PAIRS = np.array([
    [50.0000, 2.6772, -79.7751, 50.0000, 0.0000, -82.7485, 2.0425],
    [50.0000, 3.1571, -77.2803, 50.0000, 0.0000, -82.7485, 2.8615],
    [50.0000, 2.8361, -74.0200, 50.0000, 0.0000, -82.7485, 3.4412],
    [50.0000, -1.3802, -84.2814, 50.0000, 0.0000, -82.7485, 1.0000],
    [50.0000, -1.1848, -84.8006, 50.0000, 0.0000, -82.7485, 1.0000],
    [50.0000, -0.9009, -85.5211, 50.0000, 0.0000, -82.7485, 1.0000],
    [50.0000, 0.0000, 0.0000, 50.0000, -1.0000, 2.0000, 2.3669],
    [50.0000, -1.0000, 2.0000, 50.0000, 0.0000, 0.0000, 2.3669],
    [50.0000, 2.4900, -0.0010, 50.0000, -2.4900, 0.0009, 7.1792],
    [50.0000, 2.4900, -0.0010, 50.0000, -2.4900, 0.0010, 7.1792],
    [50.0000, 2.4900, -0.0010, 50.0000, -2.4900, 0.0011, 7.2195],
    [50.0000, 2.4900, -0.0010, 50.0000, -2.4900, 0.0012, 7.2195],
    [50.0000, -0.0010, 2.4900, 50.0000, 0.0009, -2.4900, 4.8045],
    [50.0000, -0.0010, 2.4900, 50.0000, 0.0010, -2.4900, 4.8045],
    [50.0000, -0.0010, 2.4900, 50.0000, 0.0011, -2.4900, 4.7461],
    [50.0000, 2.5000, 0.0000, 50.0000, 0.0000, -2.5000, 4.3065],
    [50.0000, 2.5000, 0.0000, 73.0000, 25.0000, -18.0000, 27.1492],
    [50.0000, 2.5000, 0.0000, 61.0000, -5.0000, 29.0000, 22.8977],
    [50.0000, 2.5000, 0.0000, 56.0000, -27.0000, -3.0000, 31.9030],
    [50.0000, 2.5000, 0.0000, 58.0000, 24.0000, 15.0000, 19.4535],
    [50.0000, 2.5000, 0.0000, 50.0000, 3.1736, 0.5854, 1.0000],
    [50.0000, 2.5000, 0.0000, 50.0000, 3.2972, 0.0000, 1.0000],
    [50.0000, 2.5000, 0.0000, 50.0000, 1.8634, 0.5757, 1.0000],
    [50.0000, 2.5000, 0.0000, 50.0000, 3.2592, 0.3350, 1.0000],
    [60.2574, -34.0099, 36.2677, 60.4626, -34.1751, 39.4387, 1.2644],
    [63.0109, -31.0961, -5.8663, 62.8187, -29.7946, -4.0864, 1.2630],
    [61.2901, 3.7196, -5.3901, 61.4292, 2.2480, -4.9620, 1.8731],
    [35.0831, -44.1164, 3.7933, 35.0232, -40.0716, 1.5901, 1.8645],
    [22.7233, 20.0904, -46.6940, 23.0331, 14.9730, -42.5619, 2.0373],
    [36.4612, 47.8580, 18.3852, 36.2715, 50.5065, 21.2231, 1.4146],
    [90.8027, -2.0831, 1.4410, 91.1528, -1.6435, 0.0447, 1.4441],
    [90.9257, -0.5406, -0.9208, 88.6381, -0.8985, -0.7239, 1.5381],
    [6.7747, -0.2908, -2.4247, 5.8714, -0.0985, -2.2286, 0.6377],
    [2.0776, 0.0795, -1.1350, 0.9033, -0.0636, -0.5514, 0.9082],
])


# --------------------------------------------------------------------------- CIEDE2000
def _rgb(n, h, w, seed):
    """(n, 3, h, w) float64 random sRGB in [0, 1], with a band of very dark pixels (the linear parts of the
    sRGB and CIELAB curves) and a band of pure black."""
    x = torch.from_numpy(np.random.default_rng(seed).random((n, 3, h, w)))
    x[..., :2, :] *= 0.01
    x[..., 2:3, :] = 0
    return x


def test_kornia_rgb_to_lab_matches_skimage():
    x = _rgb(2, 16, 24, 0)
    ref = rgb2lab(x.permute(0, 2, 3, 1).numpy())
    ours = rgb_to_lab(x).permute(0, 2, 3, 1).numpy()
    assert np.abs(ours - ref).max() < 1e-10
    ours32 = rgb_to_lab(x.float()).permute(0, 2, 3, 1).double().numpy()
    assert np.abs(ours32 - ref).max() < 2e-4


@pytest.mark.parametrize("dtype", [torch.float64, torch.float32])
def test_delta_e_sharma_pairs(dtype):
    pairs = torch.from_numpy(SHARMA_PAIRS).to(dtype)
    lab1, lab2 = pairs[:, 0:3], pairs[:, 3:6]
    expected = SHARMA_PAIRS[:, 6]
    for d1, d2 in ((lab1, lab2), (lab2, lab1)):  # symmetric
        ours = delta_e_ciede2000(d1, d2, dim=-1).double().numpy()
        assert np.abs(ours - expected).max() < 1e-4, np.abs(ours - expected)
    # channel-first layout (dim=-3, the default): the same values
    img = delta_e_ciede2000(lab1.T[:, :, None], lab2.T[:, :, None])[:, 0].double().numpy()
    assert np.abs(img - expected).max() < 1e-4


@pytest.mark.parametrize("dtype,tol", [(torch.float64, 1e-9), (torch.float32, 1e-4)])
def test_delta_e_matches_skimage_on_random_lab(dtype, tol):
    rng = np.random.default_rng(1)
    n = 20000
    lab1 = np.stack([rng.uniform(0, 100, n), rng.uniform(-110, 110, n), rng.uniform(-110, 110, n)], -1)
    lab2 = lab1 + rng.normal(0, 1, (n, 3)) * rng.choice([0.1, 3, 30], (n, 1))  # near and far pairs
    lab2[:, 0] = lab2[:, 0].clip(0, 100)
    lab1[:50, 1:] = 0  # zero chroma
    lab2[25:75, 1:] = 0
    ref = deltaE_ciede2000(lab1, lab2, channel_axis=-1)
    ours = delta_e_ciede2000(torch.from_numpy(lab1).to(dtype), torch.from_numpy(lab2).to(dtype), dim=-1)
    assert ours.dtype == dtype
    assert np.abs(ours.double().numpy() - ref).max() < tol


def _ciede2000_reference(a, b, mask_a, mask_b):
    """scikit-image: images masked to black, rgb2lab, deltaE_ciede2000, mean over the mask union."""
    a = (a * mask_a).double().permute(0, 2, 3, 1).numpy()
    b = (b * mask_b).double().permute(0, 2, 3, 1).numpy()
    de = deltaE_ciede2000(rgb2lab(a), rgb2lab(b), channel_axis=-1)
    union = (mask_a | mask_b)[:, 0].expand(de.shape).numpy()
    return np.array([d[u].mean() if u.any() else 0.0 for d, u in zip(de, union)])


def _masks(n, h, w, seed):
    g = torch.Generator().manual_seed(seed)
    mask_a = torch.rand(n, 1, h, w, generator=g) < 0.6
    mask_b = torch.rand(n, 1, h, w, generator=g) < 0.6
    mask_a[-1], mask_b[-1] = False, False  # the last pair: empty union
    return mask_a, mask_b


@pytest.mark.parametrize("dtype", [torch.float64, torch.float32])
def test_ciede2000_matches_skimage(dtype):
    a, b = _rgb(4, 20, 24, 2), _rgb(4, 20, 24, 3)
    b[1] = (a[1] + 0.02 * torch.randn(a[1].shape, generator=torch.Generator().manual_seed(4))).clamp(0, 1)
    mask_a, mask_b = _masks(4, 20, 24, 5)
    a, b = a.to(dtype), b.to(dtype)
    ours = ciede2000(a, b, mask_a, mask_b)
    assert ours.dtype == torch.float32 and ours.shape == (4,)
    ref = _ciede2000_reference(a, b, mask_a, mask_b)
    assert np.abs(ours.double().numpy() - ref).max() < 1e-4
    assert ref[-1] == 0 and float(ours[-1]) == 0  # empty union
    assert 0 < ref[1] < ref[0]  # the mildly distorted pair differs less


def test_ciede2000_masks():
    a, b = _rgb(3, 16, 16, 6).float(), _rgb(3, 16, 16, 7).float()
    mask_a, mask_b = _masks(3, 16, 16, 8)
    base = ciede2000(a, b, mask_a, mask_b)
    outside = ~(mask_a | mask_b)
    a2, b2 = a.clone(), b.clone()
    a2[outside.expand_as(a)] = 0.7  # pixels outside both masks: ignored
    b2[outside.expand_as(b)] = 0.3
    assert torch.equal(ciede2000(a2, b2, mask_a, mask_b), base)
    only_a = mask_a & ~mask_b  # in mask_a only: b counts as black there, whatever b holds
    b3 = b.clone()
    b3[only_a.expand_as(b)] = 0.9
    assert torch.equal(ciede2000(a, b3, mask_a, mask_b), base)
    # one pixel in one mask: ΔE00 of its colour against black
    m1 = torch.zeros(1, 1, 16, 16, dtype=torch.bool)
    m1[0, 0, 5, 7] = True
    val = ciede2000(a[:1], b[:1], m1, torch.zeros_like(m1))
    ref = deltaE_ciede2000(rgb2lab(a[0, :, 5, 7].double().numpy()), np.zeros(3))
    assert abs(float(val) - ref) < 1e-4
    # identical images in identical masks: 0; a shared (1, 1, H, W) mask broadcasts over the batch
    assert torch.equal(ciede2000(a, a, mask_a, mask_a), torch.zeros(3))
    shared = ciede2000(a, b, mask_a[:1], mask_b[:1])
    per_image = ciede2000(a, b, mask_a[:1].expand(3, -1, -1, -1), mask_b[:1].expand(3, -1, -1, -1))
    assert torch.equal(shared, per_image)


# --------------------------------------------------------------------------- piq
_PIQ_DIRECT = {  # measure -> (module, function, keyword arguments) as piq documents them
    "fsim": ("fsim", "fsim", {"chromatic": True}),
    "vif": ("vif", "vif_p", {}),
    "gmsd": ("gmsd", "gmsd", {}),
    "haarpsi": ("haarpsi", "haarpsi", {}),
    "mdsi": ("mdsi", "mdsi", {}),
    "vsi": ("vsi", "vsi", {}),
}


@pytest.fixture(scope="module")
def piq_direct():
    """``{measure: f(x, y) -> (N,)}``: piq's own functions, called as piq documents (x distorted, y reference)."""
    with piq_functions({m: (mod, fn) for m, (mod, fn, _) in _PIQ_DIRECT.items()}) as funcs:
        yield {m: (lambda x, y, f=funcs[m], kw=kw: f(x, y, data_range=1.0, reduction="none", **kw))
               for m, (_, _, kw) in _PIQ_DIRECT.items()}


def _pair(n=3, size=48, seed=9):
    """Smooth random colour images (upsampled noise) and a noisy copy, (n, 3, size, size) float32 in [0, 1]."""
    g = torch.Generator().manual_seed(seed)
    a = torch.nn.functional.interpolate(torch.rand(n, 3, size // 4, size // 4, generator=g), size=(size, size),
                                        mode="bilinear", align_corners=False)
    b = (a + 0.05 * torch.randn(a.shape, generator=g)).clamp(0, 1)
    return a, b


def test_piq_measures_equal_piq(piq_direct):
    a, b = _pair()
    ours = piq_measures(a, b)
    assert tuple(ours) == PIQ_MEASURES
    for m in PIQ_MEASURES:
        ref = piq_direct[m](b, a)  # piq's order: (distorted, reference)
        assert ours[m].dtype == torch.float32 and ours[m].shape == (3,)
        assert torch.equal(ours[m], ref), (m, ours[m], ref)
    assert set(piq_measures(a, b, measures=("vif", "gmsd"))) == {"vif", "gmsd"}


def test_piq_measures_identity_and_direction(piq_direct):
    assert LOWER_IS_BETTER_PIQ == {"gmsd", "mdsi"} and LOWER_IS_BETTER_PIQ < set(PIQ_MEASURES)
    a, b = _pair()
    same = piq_measures(a, a)
    for m in PIQ_MEASURES:
        identity = 0.0 if m in LOWER_IS_BETTER_PIQ else 1.0
        assert torch.allclose(same[m], torch.full((3,), identity), atol=1e-5, rtol=0), (m, same[m])
    assert torch.equal(same["gmsd"], torch.zeros(3)) and torch.equal(same["mdsi"], torch.zeros(3))
    # a stronger distortion scores worse in each measure's direction
    far = (a + 0.3 * torch.randn(a.shape, generator=torch.Generator().manual_seed(10))).clamp(0, 1)
    near, worse = piq_measures(a, b), piq_measures(a, far)
    for m in PIQ_MEASURES:
        sign = 1 if m in LOWER_IS_BETTER_PIQ else -1
        assert bool((sign * (worse[m] - near[m]) > 0).all()), (m, near[m], worse[m])


def test_piq_measures_crop_and_black(piq_direct):
    a, b = _pair(2, 48)
    a[..., :6, :], b[..., :6, :] = 0, 0  # black border, as on a rendered canvas
    a[..., -5:], b[..., -5:] = 0, 0
    canvas = (torch.zeros(2, 3, 64, 72), torch.zeros(2, 3, 64, 72))
    canvas[0][..., 10:58, 20:68], canvas[1][..., 10:58, 20:68] = a, b
    full = piq_measures(*canvas)
    cropped = piq_measures(a, b, crop=(10, 20, 64, 72))
    for m in PIQ_MEASURES:
        assert torch.equal(full[m], cropped[m]), m
    with pytest.raises(ValueError):
        piq_measures(a, b, crop=(20, 20, 64, 72))  # the window does not fit the canvas
    black = torch.zeros(2, 3, 48, 48)
    assert torch.equal(piq_direct["haarpsi"](black, black), torch.full((2,), float("inf")))  # piq's own value
    res = piq_measures(black, black)
    for m in PIQ_MEASURES:
        identity = 0.0 if m in LOWER_IS_BETTER_PIQ else 1.0
        assert torch.allclose(res[m], torch.full((2,), identity), atol=1e-5, rtol=0), (m, res[m])


def test_piq_measures_rejects(piq_direct):
    a, b = _pair(1, 32)
    assert 32 < PIQ_MIN_SIZE["vif"]
    with pytest.raises(ValueError, match="vif"):
        piq_measures(a, b)
    assert set(piq_measures(a, b, measures=("fsim", "gmsd", "haarpsi", "mdsi", "vsi"))) == set(PIQ_MEASURES) - {"vif"}
    with pytest.raises(ValueError, match="unknown"):
        piq_measures(a, b, measures=("lpips",))
    with pytest.raises(ValueError):
        piq_measures(a[:, :1], b[:, :1])  # grey images
