"""The regularised quality fusion (lit3d.quality.fusion) and the correlation intervals on hand-made matrices."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.stats

from lit3d.features.matrix import FeatureMatrix
from lit3d.quality.correlation import _rowwise, correlation_ci, kendall
from lit3d.quality.fusion import (AnchoredFusion, LinearFusion, fusion_from_dict, inner_score, nested_group_out,
                                 out_of_group)


def matrix(n_per_group: int = 10, noise: float = 0.02, seed: int = 0, informative: bool = True) -> FeatureMatrix:
    """Three groups; quality = 2 * good + 1 * psnr-like feature (a larger distance: worse), plus noise."""
    rng = np.random.default_rng(seed)
    n = 3 * n_per_group
    good = rng.random(n)           # a similarity: higher = better
    dist = rng.random(n)           # a distance: higher = worse
    junk = rng.random(n)
    quality = 2.0 * good - 1.0 * dist + noise * rng.normal(size=n)
    target = -quality if informative else rng.random(n)
    groups = np.repeat(["G", "V", "N"], n_per_group)
    return FeatureMatrix(np.stack([good, dist, junk], 1), ["good", "dist", "junk"], groups, target)


def test_linear_fusion_recovers_a_linear_opinion_and_round_trips():
    fm = matrix()
    model = LinearFusion(["good", "dist", "junk"], [1.0, -1.0, 1.0], "ridge", strength=0.1).fit(fm)
    pred = model.predict(fm)
    assert scipy.stats.spearmanr(pred, fm.target)[0] > 0.99
    w = dict(zip(model.features, model.coef))
    assert w["good"] > 0 and w["dist"] > 0 and w["good"] > 1.5 * w["dist"] and abs(w["junk"]) < 0.05 * w["good"]
    again = LinearFusion.from_dict(model.to_dict())
    np.testing.assert_allclose(again.predict(fm), pred, rtol=0, atol=1e-12)


def test_positive_weights_cannot_take_a_contradicting_sign():
    fm = matrix()
    # the distance given the wrong orientation: ridge(positive=True) must leave it out instead of flipping it
    model = LinearFusion(["good", "dist"], [1.0, 1.0], "ridge", strength=0.1).fit(fm)
    assert model.coef[1] == pytest.approx(0.0, abs=1e-9) and model.coef[0] > 0


def test_strength_is_chosen_inside_the_training_rows():
    model = LinearFusion(["good", "dist", "junk"], [1.0, -1.0, 1.0], "ridge").fit(matrix())
    assert model.strength is not None and len(model.inner) > 1 and max(model.inner.values()) > 0.9


def test_out_of_group_never_trains_on_the_group_it_predicts():
    fm = matrix()
    seen = []

    class Spy:
        def fit(self, train):
            self.train_groups = set(train.shapes)
            return self

        def predict(self, test):
            seen.append((self.train_groups, set(test.shapes)))
            return np.zeros(len(test))

    out_of_group(fm, Spy)
    assert len(seen) == 3 and all(not (tr & te) for tr, te in seen)


def test_nested_protocol_chooses_without_the_held_out_group_and_a_broken_target_scores_near_zero():
    fm = matrix(noise=0.05)
    cands = {"ridge": lambda: LinearFusion(["good", "dist", "junk"], [1.0, -1.0, 1.0], "ridge"),
             "junk only": lambda: LinearFusion(["junk"], [1.0], "ridge")}
    pred, choices = nested_group_out(fm, cands)
    assert set(choices) == {"G", "V", "N"} and all(c["chosen"] == "ridge" for c in choices.values())
    assert scipy.stats.spearmanr(pred, fm.target)[0] > 0.95
    broken = matrix(informative=False)
    pred, _ = nested_group_out(broken, cands)
    assert abs(scipy.stats.spearmanr(pred, broken.target)[0]) < 0.5
    assert inner_score(broken, cands["ridge"]) < 0.5


def anchored_matrix(correction: float = 0.0, seed: int = 0) -> FeatureMatrix:
    """Three groups; quality = -anchor (a distance) + correction * extra."""
    rng = np.random.default_rng(seed)
    n = 30
    groups = np.repeat(["G", "V", "N"], 10)
    anchor = rng.random(n)
    extra = rng.random(n)
    quality = -anchor + correction * extra
    return FeatureMatrix(np.stack([anchor, extra], 1), ["anchor", "extra"], groups, -quality)


def test_anchored_fusion_alone_keeps_the_anchors_order_across_folds():
    # a per-fold linear map would rescale each held-out group differently; the anchored score does not
    fm = anchored_matrix(correction=0.0)
    pred = out_of_group(fm, lambda: AnchoredFusion("anchor", -1.0, ["extra"], [1.0], strength=float("inf")))
    np.testing.assert_allclose(pred, fm.columns(["anchor"])[:, 0], atol=1e-12)  # -score = the raw anchor
    model = AnchoredFusion("anchor", -1.0, ["extra"], [1.0], strength=float("inf")).fit(fm)
    q = model.quality(fm.columns(model.inputs))  # the opinion map is fitted here, at its first use
    assert model.corrections.tolist() == [0.0] and model.opinion["kind"] in ("logistic", "linear")
    assert scipy.stats.pearsonr(q, 1.0 - fm.target)[0] > 0.99


def test_anchored_fusion_learns_a_correction_in_the_anchors_units_and_round_trips():
    fm = anchored_matrix(correction=0.5)
    model = AnchoredFusion("anchor", -1.0, ["extra"], [1.0], strength=0.01).fit(fm)
    assert model.corrections[0] == pytest.approx(0.5, abs=0.02)  # quality = -anchor + 0.5 extra
    again = fusion_from_dict(model.to_dict())
    assert isinstance(again, AnchoredFusion)
    np.testing.assert_allclose(again.predict(fm), model.predict(fm), atol=1e-12)
    alone = fusion_from_dict(AnchoredFusion("anchor", -1.0, ["extra"], [1.0], float("inf")).fit(fm).to_dict())
    assert alone.strength == float("inf") and isinstance(fusion_from_dict(
        LinearFusion(["extra"], [1.0], "ridge", 0.1).fit(fm).to_dict()), LinearFusion)


def test_anchored_fusion_refuses_a_correction_against_its_sign_and_chooses_its_strength_inside():
    fm = anchored_matrix(correction=-0.5)  # "extra" lowers quality but is declared "higher = better"
    model = AnchoredFusion("anchor", -1.0, ["extra"], [1.0], strength=0.01).fit(fm)
    assert model.corrections[0] == pytest.approx(0.0, abs=1e-9)
    chosen = AnchoredFusion("anchor", -1.0, ["extra"], [1.0]).fit(anchored_matrix(correction=1.0, seed=1))
    assert np.isfinite(chosen.strength) and chosen.corrections[0] > 0.5 and "inf" in chosen.inner
    with pytest.raises(ValueError, match="finite values"):
        fusion_from_dict({**model.to_dict(), "corrections": [float("nan")]})


def test_opinion_map_is_an_increasing_logistic_that_fits_a_saturating_opinion():
    from lit3d.quality.opinion_map import apply_opinion_map, check_opinion_map, fit_opinion_map

    rng = np.random.default_rng(0)
    s = np.sort(rng.normal(size=40))
    q = 0.1 + 0.8 / (1.0 + np.exp(-(s - 0.3) / 0.4)) + 0.01 * rng.normal(size=40)
    m = fit_opinion_map(s, q)
    assert m["kind"] == "logistic"
    np.testing.assert_allclose(m["params"], [0.1, 0.9, 0.3, 0.4], atol=0.05)
    fitted = apply_opinion_map(m, s)
    assert (np.diff(fitted) >= 0).all() and np.abs(fitted - q).max() < 0.05
    line = fit_opinion_map(s[:4], q[:4])  # too few scores for four parameters: a line
    assert line["kind"] == "linear" and line["params"][1] > 0
    with pytest.raises(ValueError, match="opinion map"):
        check_opinion_map({"kind": "logistic", "params": [1.0, 2.0]})


def test_row_wise_correlations_equal_scipy_and_intervals_hold_the_estimate():
    rng = np.random.default_rng(1)
    x = rng.normal(size=30)
    y = x + rng.normal(size=30)
    idx = rng.integers(0, 30, size=(40, 30))
    refs = {"srocc": lambda a, b: scipy.stats.spearmanr(a, b)[0], "plcc": lambda a, b: scipy.stats.pearsonr(a, b)[0],
            "krocc": lambda a, b: scipy.stats.kendalltau(a, b)[0]}
    for kind, ref in refs.items():
        np.testing.assert_allclose(_rowwise(kind, x[idx], y[idx]), [ref(x[i], y[i]) for i in idx], atol=1e-12)
        r, lo, hi = correlation_ci(x, y, kind, n_resamples=500)
        assert r == pytest.approx(ref(x, y)) and lo < r < hi
    assert kendall(x, np.ones(30)) == 0.0
    r, lo, hi = correlation_ci(x[:2], y[:2])
    assert np.isnan(lo) and np.isnan(hi)


def test_positive_ridge_equals_scikit_learn():
    from sklearn.linear_model import Ridge

    from lit3d.quality.fusion import PositiveRidge

    rng = np.random.default_rng(3)
    x = rng.normal(size=(27, 6))
    y = x @ np.array([1.0, -0.5, 0.3, 0.0, 2.0, -1.0]) + 0.1 * rng.normal(size=27)
    for alpha in (0.1, 3.0):
        ours, ref = PositiveRidge(alpha).fit(x, y), Ridge(alpha=alpha, positive=True, tol=1e-10).fit(x, y)
        np.testing.assert_allclose(ours.coef_, ref.coef_, atol=1e-5)
        assert ours.intercept_ == pytest.approx(ref.intercept_, abs=1e-5)

