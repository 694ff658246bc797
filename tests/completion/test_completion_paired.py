"""Paired per-sample comparison of completion results: extrusion baseline, bootstrap intervals."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from lit3d.completion.paired import PairedSamples, extrude_silhouette
from lit3d.metrics.bootstrap import mean_ci, paired_difference_ci


def test_extrusion_fills_behind_the_first_visible_voxel_down_to_the_deepest_one():
    g = torch.Generator().manual_seed(0)
    partial = (torch.rand(2, 1, 5, 5, 5, generator=g) > 0.8).float()
    partial[0, ..., 3:] = 0  # sample 0 is shallow: its extrusion stops at k = 2
    got = extrude_silhouette(partial, 10)
    ref = np.zeros((2, 1, 5, 5, 5), np.float32)
    p = partial.numpy()
    for b in range(2):
        for i in range(5):
            for j in range(5):
                ks = np.nonzero(p[b, 0, i, j])[0]
                deepest = max(np.nonzero(p[b, 0])[2], default=-1)
                if len(ks):
                    ref[b, 0, i, j, ks[0]:deepest + 1] = 1
    ref = ref.repeat(2, 2).repeat(2, 3).repeat(2, 4)  # nearest x2
    assert got.shape == (2, 1, 10, 10, 10) and got[0, ..., 6:].sum() == 0 and got[1, ..., 8:].sum() > 0
    np.testing.assert_array_equal(got.numpy(), ref)


def test_bootstrap_interval_matches_the_normal_theory_interval_on_a_large_sample():
    x = np.random.default_rng(1).normal(0.3, 0.1, 4000)
    m, lo, hi = mean_ci(x)
    se = x.std(ddof=1) / np.sqrt(len(x))
    assert m == pytest.approx(x.mean())
    assert lo == pytest.approx(x.mean() - 1.96 * se, abs=0.4 * se)
    assert hi == pytest.approx(x.mean() + 1.96 * se, abs=0.4 * se)
    # paired: the interval of the mean difference, much narrower than unpaired when a and b co-vary
    a = np.random.default_rng(2).normal(0.5, 0.2, 300)
    b = a - 0.02 + np.random.default_rng(3).normal(0, 0.01, 300)
    d, dlo, dhi = paired_difference_ci(a, b)
    assert d == pytest.approx(0.02, abs=0.003) and 0.0 < dlo < d < dhi < 0.03
    assert np.isnan(mean_ci([0.4])[1])  # one sample: no interval


def test_paired_summary_equals_numpy_on_the_same_samples():
    g = torch.Generator().manual_seed(5)
    target = (torch.rand(6, 1, 8, 8, 8, generator=g) > 0.6).float()
    preds = {"model": torch.rand(6, 1, 8, 8, 8, generator=g),
             "input": (torch.rand(6, 1, 8, 8, 8, generator=g) > 0.9).float(),
             "extrusion": (torch.rand(6, 1, 8, 8, 8, generator=g) > 0.5).float()}
    thr = {"model": 0.45, "input": 0.5, "extrusion": 0.5}
    cats = torch.tensor([0, 1, 0, 1, 1, 0])
    ps = PairedSamples()
    ps.update(0, cats[:3], {k: v[:3] for k, v in preds.items()}, target[:3], thr)
    ps.update(0, cats[3:], {k: v[3:] for k, v in preds.items()}, target[3:], thr)
    out = ps.summary(["same", "cross"], ["chair", "table"])
    y = target.numpy() > 0.5

    def iou(p, t):
        b = p.numpy() >= t
        return (b & y).reshape(6, -1).sum(1) / (b | y).reshape(6, -1).sum(1)

    ious = {k: iou(v, thr[k]) for k, v in preds.items()}
    assert out["test/same/paired/n"] == 6 and "test/cross/paired/n" not in out
    assert out["test/same/paired/model"] == pytest.approx(ious["model"].mean(), abs=1e-6)
    k = cats.numpy() == 1
    assert out["test/same/paired/margin_input/table"] == pytest.approx((ious["model"] - ious["input"])[k].mean(), abs=1e-6)
    assert out["test/same/paired/extrusion/chair"] == pytest.approx(ious["extrusion"][~k].mean(), abs=1e-6)
    lo, hi = out["test/same/paired/margin_extrusion_lo"], out["test/same/paired/margin_extrusion_hi"]
    assert lo <= out["test/same/paired/margin_extrusion"] <= hi
