"""FSIM (lit3d.metrics.image.fsim, our torch port of the authors' MATLAB FeatureSIM) against piq's
``fsim`` on real photographs shipped with scikit-image, under matching settings.

Matching settings: grey images (1 channel) and ``chromatic=False``: piq's colour FSIMc adds I/Q
chroma terms and its grey conversion of RGB is YIQ's Y, while ours averages the channels (so colour
images differ by design). Sizes where the subsampling factor ``F = round(min(H, W) / 256)`` is 1 or
2: there MATLAB's ``conv2(..., 'same')`` + ``Y(1:F:end, 1:F:end)`` (ours) and piq's
``avg_pool2d(F)`` take the same blocks; from F = 3 on (min side >= 640 px) MATLAB's blocks are
offset by ``(F - 1) // 2`` pixels and piq's are not, so the two differ by design there.

Tolerance 2e-5: measured differences on these pairs are at most 7.5e-6 (coins + noise). Both run float32 FFTs
of the same log-Gabor bank (ours built in float64, then cast); the mean-phase epsilon differs
(MATLAB's 1e-4, which we keep, against piq's float32 machine epsilon), which matters only where the
filter energy is near zero, and most under added noise.

piq is a test-only dependency installed by ``scripts/bootstrap.sh`` with ``--no-deps``: its package
``__init__`` imports torchvision (for its perceptual metrics), whose PyPI wheels are CUDA builds that
would replace the CPU torch or fail to load beside it. ``piq/fsim.py`` needs only torch, so it is
loaded here without running that ``__init__``.
"""
from __future__ import annotations

import io

import numpy as np
import pytest
import torch

from tests.helpers.piq import piq_functions

from lit3d.metrics.image import fsim

TOLERANCE = 2e-5


@pytest.fixture(scope="module")
def piq_fsim():
    with piq_functions({"fsim": ("fsim", "fsim")}) as funcs:
        yield funcs["fsim"]


def _pairs():
    """(name, reference, distorted) grey float32 (1, 1, H, W) in [0, 1]: real photographs, distorted.
    camera 384 x 384 (F = 2), coins 256 x 320 and text 172 x 448 (F = 1, not square)."""
    from PIL import Image, ImageFilter
    from skimage import data

    def jpeg(ref):
        buf = io.BytesIO()
        ref.save(buf, format="JPEG", quality=10)
        return Image.open(buf)

    def noise(ref):
        img = np.asarray(ref, np.float64)
        return Image.fromarray(np.clip(img + np.random.default_rng(0).normal(0, 20, img.shape), 0, 255).astype(np.uint8))

    def blur(ref):
        return ref.filter(ImageFilter.GaussianBlur(1.5))

    out = []
    for name, crop, distortions in (("camera", (slice(64, 448), slice(64, 448)), (blur, noise)),
                                    ("coins", (slice(0, 256), slice(0, 320)), (jpeg, noise)), ("text", None, (jpeg, blur))):
        img = getattr(data, name)()
        ref = Image.fromarray(np.ascontiguousarray(img if crop is None else img[crop]))
        for distort in distortions:
            a = torch.from_numpy(np.asarray(ref, np.float32) / 255)[None, None]
            b = torch.from_numpy(np.asarray(distort(ref), np.float32) / 255)[None, None]
            out.append((f"{name}{tuple(a.shape[-2:])}/{distort.__name__}", a, b))
    return out


def test_fsim_matches_piq_on_real_images(piq_fsim):
    pairs = _pairs()
    sizes = {tuple(a.shape[-2:]) for _, a, _ in pairs}
    assert {max(1, round(min(s) / 256)) for s in sizes} == {1, 2}  # both subsampling factors are covered
    values = []
    for name, a, b in pairs:
        ours = float(fsim(a, b))
        ref = float(piq_fsim(a, b, data_range=1.0, chromatic=False, reduction="none"))
        assert abs(ours - ref) < TOLERANCE, (name, ours, ref)
        values.append(ref)
    assert min(values) < 0.8 < max(values)  # the distortions span a real range of scores
