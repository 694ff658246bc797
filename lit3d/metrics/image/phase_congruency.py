"""Phase congruency (Kovesi) from a log-Gabor bank, as FSIM's ``phasecong2`` uses it.

Grey images ``(B, H, W)`` float; the result is ``(B, H, W) float32`` in ``[0, 1]``.
No library in the dependencies provides it (kornia, torchmetrics, scipy and
scikit-image have none; piq's FSIM is not a dependency), so it is our own torch
port of the authors' MATLAB code.
"""
from __future__ import annotations

import functools
import math

import torch


@functools.lru_cache(maxsize=64)
def _fsim_filters(h: int, w: int, device: str, nscale: int = 4, norient: int = 4, min_wavelength: float = 6.0,
                  mult: float = 2.0, sigma_onf: float = 0.55, d_theta_on_sigma: float = 1.2):
    """Log-Gabor filter bank ``(O, S, H, W)`` and the per-orientation noise constants."""
    def axis(n):
        if n % 2:
            return torch.arange(-(n - 1) / 2, (n - 1) / 2 + 1, dtype=torch.float64) / (n - 1)
        return torch.arange(-n / 2, n / 2, dtype=torch.float64) / n

    yy, xx = torch.meshgrid(axis(h), axis(w), indexing="ij")
    radius = torch.fft.ifftshift(torch.sqrt(xx**2 + yy**2))
    theta = torch.fft.ifftshift(torch.atan2(-yy, xx))
    radius[0, 0] = 1.0
    lp = 1.0 / (1.0 + (radius / 0.45) ** (2 * 15))
    log_gabor = []
    for s in range(nscale):
        fo = 1.0 / (min_wavelength * mult**s)
        g = torch.exp(-(torch.log(radius / fo)) ** 2 / (2 * math.log(sigma_onf) ** 2)) * lp
        g[0, 0] = 0.0
        log_gabor.append(g)
    theta_sigma = math.pi / norient / d_theta_on_sigma
    filters, em_n, sum_an2, sum_aiaj = [], [], [], []
    for o in range(norient):
        ang = o * math.pi / norient
        ds = torch.sin(theta) * math.cos(ang) - torch.cos(theta) * math.sin(ang)
        dc = torch.cos(theta) * math.cos(ang) + torch.sin(theta) * math.sin(ang)
        spread = torch.exp(-torch.atan2(ds, dc).abs() ** 2 / (2 * theta_sigma**2))
        fo_bank = torch.stack([g * spread for g in log_gabor])  # (S, H, W)
        ifft_f = torch.fft.ifft2(fo_bank).real * math.sqrt(h * w)
        filters.append(fo_bank)
        em_n.append(float((fo_bank[0] ** 2).sum()))
        sum_an2.append(float((ifft_f**2).sum()))
        aiaj = sum(float((ifft_f[i] * ifft_f[j]).sum()) for i in range(nscale) for j in range(i + 1, nscale))
        sum_aiaj.append(aiaj)
    bank = torch.stack(filters).to(device=device, dtype=torch.float32)
    return bank, torch.tensor(em_n), torch.tensor(sum_an2), torch.tensor(sum_aiaj)


def phase_congruency(img: torch.Tensor, k: float = 2.0, eps: float = 1e-4,
                     full_pixels: int | None = None) -> torch.Tensor:
    """Phase congruency ``(B, H, W)`` of grey images ``(B, H, W)`` (Kovesi; FSIM's ``phasecong2``).

    Per orientation: ``E = |sum_s eo_s| - sum_s |Im(eo_s conj(m))|`` with ``m`` the unit
    mean phase (the same value as the MATLAB loop, in fewer passes), noise threshold
    ``T`` from the median of the smallest-scale energy, ``PC = sum_o (E - T)+ / sum_o,s |eo|``.

    ``full_pixels``: ``img`` is a crop of a larger canvas of this many pixels whose
    responses outside the crop are taken as 0; the noise median is then that of the
    whole canvas (rank shifted by the number of outside pixels; 0 when they are the
    majority, which skips the selection).
    """
    bsz, h, w = img.shape
    n = h * w
    rank = (n + 1) // 2 if full_pixels is None else (int(full_pixels) + 1) // 2 - (int(full_pixels) - n)
    # images are independent: chunks whose (chunk, scales, H, W) complex responses stay in cache
    # run about 1.3x faster on CPU than one big batch (same numbers)
    step = bsz if img.device.type != "cpu" else max(1, _PC_CHUNK_ELEMS // (4 * n))
    if step >= bsz:
        return _phase_congruency(img, k, eps, rank)
    return torch.cat([_phase_congruency(x, k, eps, rank) for x in img.split(step)])


_PC_CHUNK_ELEMS = 1 << 18  # complex responses per chunk on CPU (2 MB)


@functools.lru_cache(maxsize=64)
def _fsim_filters_complex(h: int, w: int, device: str):
    bank, em_n, sum_an2, sum_aiaj = _fsim_filters(h, w, device)
    # complex x complex products are about 4x faster on CPU than complex x real (no promotion copy)
    return bank.to(torch.complex64), em_n.tolist(), sum_an2.tolist(), sum_aiaj.tolist()


def _kth_smallest(x: torch.Tensor, k: int) -> torch.Tensor:
    """``(B,)``: the ``k``-th smallest (1-based) of each row of ``(B, n)``. On CPU through NumPy's
    introselect (``np.partition``), about 6x faster than ``torch.kthvalue`` there; same values."""
    if x.device.type != "cpu":
        return x.kthvalue(k, dim=1).values
    import numpy as np

    return torch.from_numpy(np.partition(x.detach().numpy(), k - 1, axis=1)[:, k - 1].copy())


def _phase_congruency(img: torch.Tensor, k: float, eps: float, rank: int) -> torch.Tensor:
    bsz, h, w = img.shape
    bank, em_n, sum_an2, sum_aiaj = _fsim_filters_complex(h, w, str(img.device))
    spec = torch.fft.fft2(img.float())[:, None]
    energy_all = torch.zeros(bsz, h, w, dtype=torch.float32, device=img.device)
    an_all = torch.zeros_like(energy_all)
    for o in range(bank.shape[0]):
        eo = torch.fft.ifft2(spec * bank[o])  # (B, S, H, W) complex
        e, od = eo.real, eo.imag
        an2 = torch.addcmul(e * e, od, od)  # |eo|^2
        sum_eo = eo.sum(1)
        xe = sum_eo.abs()
        den = xe + eps
        mean_e, mean_o = sum_eo.real / den, sum_eo.imag / den
        # sum_s (e me + o mo) = |sum eo|^2 / (|sum eo| + eps); deviation term per scale
        dev = torch.addcmul(od * mean_e[:, None], e, mean_o[:, None], value=-1.0).abs_().sum(1)
        energy = xe * xe / den - dev
        if rank >= 1:
            median = _kth_smallest(an2[:, 0].flatten(1), rank)  # MATLAB median (odd) / lower middle
            mean_e2n = -median / math.log(0.5)
            noise_power = mean_e2n / em_n[o]
            est_noise2 = 2 * noise_power * sum_an2[o] + 4 * noise_power * sum_aiaj[o]
            tau = torch.sqrt(est_noise2 / 2)
            t = (tau * math.sqrt(math.pi / 2) + k * torch.sqrt((2 - math.pi / 2) * tau**2)) / 1.7
            energy = energy - t[:, None, None]
        energy_all += energy.clamp_min_(0.0)
        an_all += an2.sqrt_().sum(1)
    return energy_all / an_all.clamp_min(1e-12)

