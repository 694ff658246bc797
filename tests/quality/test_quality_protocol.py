"""Protocol of thesis ch. 4 on plain feature matrices: correlations, MLP, SFS (Algorithm 4.1), LOSO."""
from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.stats
import torch

from lit3d.quality.nets import BatchedQualityMLP, QualityMLP
from lit3d.quality.protocol import (
    FeatureBaseline,
    FeatureMatrix,
    LearnedScore,
    SingleBestFeature,
    TargetScaling,
    TrainConfig,
    cross_dataset,
    fit_mlp,
    leave_one_shape_out,
    pearson,
    predict,
    scale_targets,
    spearman,
    training_corr,
)
from lit3d.quality.selection import sequential_forward_search

FAST = TrainConfig(lr=0.05, momentum=0.9, epochs=25, hidden=16, blocks=1, dropout=0.0)


def toy_matrix(seed: int = 0, n_shapes: int = 4, per_shape: int = 12, n_noise: int = 6) -> FeatureMatrix:
    """Target = severity; 'good_a' and 'good_b' each carry half of it, the rest is noise."""
    rng = np.random.default_rng(seed)
    shapes = np.repeat([f"s{i}" for i in range(n_shapes)], per_shape)
    y = np.tile(np.linspace(0.05, 1.0, per_shape), n_shapes)
    kind = np.tile(np.arange(per_shape) % 2, n_shapes)  # two "distortion types"
    a = np.where(kind == 0, y, 0.0) + rng.normal(0, 0.03, y.size)
    b = np.where(kind == 1, y, 0.0) + rng.normal(0, 0.03, y.size)
    noise = rng.normal(size=(y.size, n_noise))
    X = np.column_stack([a, b, noise])
    names = ["good_a", "good_b"] + [f"noise_{i}" for i in range(n_noise)]
    return FeatureMatrix(X, names, shapes, y, dataset="toy", target_name="severity")


def test_correlations_match_scipy():
    rng = np.random.default_rng(1)
    a, b = rng.normal(size=30), rng.normal(size=30)
    b[:5] = b[0]  # ties
    assert pearson(a, b) == pytest.approx(scipy.stats.pearsonr(a, b)[0], abs=1e-12)
    assert spearman(a, b) == pytest.approx(scipy.stats.spearmanr(a, b)[0], abs=1e-12)
    assert pearson(np.ones(5), a[:5]) == 0.0  # constant -> defined, not NaN


def test_target_scaling_orients_and_inverts():
    y, sc = scale_targets([0, 2, 4], lo=0, hi=4, higher_is_better=True, name="MOS")
    np.testing.assert_allclose(y, [1.0, 0.5, 0.0])  # MOS 4 = identical -> 0 distortion
    assert sc.inverse(0.25) == pytest.approx(3.0)
    assert TargetScaling.from_dict(sc.to_dict()) == sc


def test_from_tables_clips_inf_and_reports_missing():
    fm = FeatureMatrix.from_tables([{"psnr": math.inf, "m": 1.0}, {"psnr": 30.0, "m": 2.0}], ["a", "b"], [0, 1])
    assert fm.columns(["psnr"])[0, 0] == 30.0
    with pytest.raises(KeyError, match="feature 'x' missing for item"):
        FeatureMatrix.from_tables([{"x": 1.0}, {"y": 2.0}], ["a", "b"], [0, 1], names=["x"])


def test_batched_mlp_equals_single():
    torch.manual_seed(0)
    b = BatchedQualityMLP(3, 5, hidden=8, blocks=2, dropout=0.0, seed=3)
    x = torch.randn(3, 7, 5)
    b.train()
    b(x)  # update running stats once
    b.eval()
    out = b(x)
    for i in range(3):
        single = b.to_single(i).eval()
        torch.testing.assert_close(single(x[i]), out[i], rtol=1e-5, atol=1e-6)
    net = QualityMLP(5, hidden=8, blocks=2, batch_norm=False)
    assert net(torch.randn(4, 5)).shape == (4,)


def test_mlp_training_is_deterministic_and_learns():
    fm = toy_matrix()
    p1 = predict(fit_mlp(fm.X, fm.target, FAST), fm.X)
    p2 = predict(fit_mlp(fm.X, fm.target, FAST), fm.X)
    np.testing.assert_array_equal(p1, p2)
    assert pearson(p1, fm.target) > 0.8


def test_sfs_is_algorithm_4_1_on_a_known_corr():
    # corr = sum of feature gains, with diminishing returns: picks c, a, then stops (b would lower it)
    gains = {"a": 0.3, "b": -0.1, "c": 0.5, "d": 0.0}

    def corr_many(sets):
        return [sum(gains[f] for f in s) - (0.35 if len(s) > 2 else 0.0) for s in sets]

    res = sequential_forward_search(["a", "b", "c", "d"], corr_many, keep_steps=True)
    assert res.selected == ["c", "a"]
    assert res.scores == pytest.approx([0.5, 0.8])
    assert len(res.steps) == 3  # third step found no improvement and stopped
    # ties keep the earlier feature; max_features caps
    assert sequential_forward_search(["x", "y"], lambda s: [1.0] * len(s), max_features=1).selected == ["x"]


def test_sfs_with_mlp_prefers_informative_features():
    fm = toy_matrix()
    res = sequential_forward_search(fm.names, training_corr(fm, FAST), max_features=2)
    assert set(res.selected) == {"good_a", "good_b"}


def test_sfs_never_sees_the_held_out_shape():
    """Poison the held-out shape's features: every fold's selection must be unchanged."""
    fm = toy_matrix(per_shape=10)
    for held_out in fm.shape_names[::3]:  # first and last fold
        selections = []
        for poison in (False, True):
            X = fm.X.copy()
            if poison:
                rng = np.random.default_rng(7)
                m = fm.shapes == held_out
                X[m] = rng.normal(0, 1e3, size=X[m].shape)  # wild values, and perfect leakage:
                X[m, 2] = fm.target[m] * 1e3                 # noise_0 == target on the test shape
            poisoned = FeatureMatrix(X, fm.names, fm.shapes, fm.target)
            chosen = {}
            leave_one_shape_out(poisoned, {"sfs": lambda: LearnedScore(FAST, "sfs", max_features=3)},
                                shapes=[held_out], on_fold=lambda s, n, m: chosen.update({s: list(m.features)}))
            selections.append(chosen[held_out])
        assert selections[0] == selections[1], held_out


def test_loso_learned_beats_single_measures_on_toy():
    fm = toy_matrix()
    res = leave_one_shape_out(fm, {
        "ours": lambda: LearnedScore(FAST, "sfs", max_features=2),
        "a": lambda: FeatureBaseline("good_a"),
        "best": lambda: SingleBestFeature(),
    })
    assert set(res["ours"].per_shape) == set(fm.shape_names)
    assert res["ours"].mean_spearman > res["a"].mean_spearman
    assert res["ours"].mean_spearman > res["best"].mean_spearman
    m = res["ours"].metrics("test/cv")
    assert "test/cv/ours/pearson/s0" in m and "test/cv/ours/spearman" in m


def test_cross_dataset_uses_common_features():
    a, b = toy_matrix(0), toy_matrix(1)
    b = b.select(["good_a", "good_b", "noise_0"])
    res = cross_dataset(a, {"other": b}, {"ours": lambda: LearnedScore(FAST, "all")})
    assert set(res["other"]["ours"].per_shape) == set(b.shape_names)
    assert res["other"]["ours"].mean_pearson > 0.5
