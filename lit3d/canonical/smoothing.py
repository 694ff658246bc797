"""The predicted canonical depth smoothed inside its predicted silhouette before it is scored
(``evaluation.prediction_smooth_px``): a retrieval setting, chosen on validation people.

The warp head's depth surface carries ridges and the seams of the moved limbs, which the retrieval
descriptor (the back-projected surface rendered from 66 views) reads as shape; who the person is shows
in the outline and the coarse relief. A Gaussian of ``sigma`` pixels (at the image's size) over the
silhouette only (:func:`lit3d.metrics.image.filters.masked_gaussian_blur`) removes them. It is applied
to the model's prediction row where it is scored and saved (retrieval, ``heldout.npz``, the pooled
protocol), not to the posed input or the true canonical rows, not in training, and not where the
depth is used as a surface (``lit3d-reconstruct --canonical``, the contact sheets: the net's own depth).
"""
from __future__ import annotations

import numpy as np
import torch

from lit3d.metrics.image.filters import masked_gaussian_blur

SETTING = "prediction_smooth_px"


def smooth_prediction(depth, mask, sigma: float, threshold: float = 0.5):
    """``depth`` ``(..., S, S)`` (torch or numpy) blurred with a Gaussian of ``sigma`` px over the pixels
    where the mask probability ``mask`` (same shape) is >= ``threshold``; same type and dtype.
    ``sigma <= 0``: ``depth`` unchanged."""
    if not sigma or sigma <= 0:
        return depth
    if isinstance(depth, np.ndarray):
        out = smooth_prediction(torch.from_numpy(depth.astype(np.float32)),
                                torch.from_numpy(np.asarray(mask, np.float32)), sigma, threshold)
        return out.numpy().astype(depth.dtype)
    inside = (mask.float() >= threshold).float()
    return masked_gaussian_blur(depth, inside, float(sigma))


def smoothing_of(settings) -> float:
    """The settings' ``prediction_smooth_px`` (0 when absent or null)."""
    return float((settings or {}).get(SETTING) or 0.0)
