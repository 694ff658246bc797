"""masked_gaussian_blur: the normalised convolution against scipy.ndimage (an independent reference)."""
import numpy as np
import pytest
import torch
from scipy.ndimage import gaussian_filter

from lit3d.metrics.image.filters import masked_gaussian_blur


@pytest.mark.parametrize("sigma", [1.0, 2.5, 4.0])
def test_matches_scipy_normalised_convolution(sigma):
    rng = np.random.default_rng(0)
    depth = rng.random((3, 40, 150)).astype(np.float32)  # 150 px: the blocked CPU path too
    mask = (rng.random((3, 40, 150)) > 0.3).astype(np.float32)
    got = masked_gaussian_blur(torch.from_numpy(depth), torch.from_numpy(mask), sigma).numpy()
    for d, m, g in zip(depth, mask, got):
        num = gaussian_filter(d * m, sigma, mode="constant", truncate=4.0)
        den = gaussian_filter(m, sigma, mode="constant", truncate=4.0)
        np.testing.assert_allclose(g, np.where(m > 0, num / den, d), atol=1e-5)


def test_background_and_flat_surfaces_stay_put():
    depth = torch.zeros(1, 1, 32, 32)
    mask = torch.zeros(1, 1, 32, 32)
    mask[..., 8:24, 8:24] = 1
    depth[..., 8:24, 8:24] = 0.6
    out = masked_gaussian_blur(depth, mask, 3.0)
    assert torch.allclose(out, depth, atol=1e-6)  # no background pulled into the rim; outside unchanged
    assert masked_gaussian_blur(depth, mask, 0.0) is depth
