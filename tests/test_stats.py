"""semmatch.evaluate.stats: stratified t intervals and tests, Holm, and percentile bootstrap intervals."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from scipy import stats as st

from semmatch.evaluate.stats import (
    INTERVAL_METHODS,
    bootstrap_ci,
    holm,
    interval,
    paired_difference_ci,
    ratio_of_means_ci,
    scene_kind,
    stratified_estimate,
    stratified_t_ci,
    t_test_pvalue,
)


def test_constant_sample_gives_zero_width_interval_without_warning():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert bootstrap_ci([0.7] * 5) == (0.7, 0.7, 0.7)
        assert bootstrap_ci([0.42]) == (0.42, 0.42, 0.42)
        assert bootstrap_ci([np.nan, 0.3, np.nan]) == (0.3, 0.3, 0.3)


def test_normal_sample_interval_matches_the_normal_approximation():
    n = 400
    x = np.random.default_rng(123).normal(5.0, 1.0, n)
    mean, lo, hi = bootstrap_ci(x, seed=1)
    assert mean == pytest.approx(x.mean())
    assert lo < mean < hi
    half = 1.96 / np.sqrt(n)
    assert (hi - lo) / 2 == pytest.approx(half, rel=0.15)
    assert (mean - lo) == pytest.approx(half, rel=0.2)
    assert (hi - mean) == pytest.approx(half, rel=0.2)


def test_confidence_level_widens_the_interval():
    x = np.random.default_rng(5).normal(0.0, 1.0, 50)
    _, lo80, hi80 = bootstrap_ci(x, confidence=0.8)
    _, lo99, hi99 = bootstrap_ci(x, confidence=0.99)
    assert lo99 < lo80 < hi80 < hi99


def test_same_seed_same_numbers_other_seed_other_numbers():
    x = np.random.default_rng(7).uniform(0.6, 0.9, 8)
    assert bootstrap_ci(x, seed=3) == bootstrap_ci(x, seed=3)
    assert bootstrap_ci(x, seed=3) != bootstrap_ci(x, seed=4)


def test_nans_are_dropped():
    x = np.array([0.1, 0.5, 0.2, 0.9, 0.4])
    assert bootstrap_ci(np.insert(x, [1, 3], np.nan)) == bootstrap_ci(x)


@pytest.mark.parametrize("values", [[], [np.nan, np.nan]])
def test_no_values_raise(values):
    with pytest.raises(ValueError, match="no values"):
        bootstrap_ci(values)


def test_bad_confidence_raises():
    with pytest.raises(ValueError, match="confidence"):
        bootstrap_ci([1.0, 2.0], confidence=95)


def test_paired_difference_is_the_interval_of_the_differences():
    rng = np.random.default_rng(2)
    a = rng.uniform(0.7, 0.9, 6)
    b = a - 0.05 + rng.normal(0, 0.01, 6)
    d, lo, hi = paired_difference_ci(a, b, seed=9)
    assert (d, lo, hi) == bootstrap_ci(a - b, seed=9)
    assert d == pytest.approx(np.mean(a - b))
    assert 0 < lo <= d <= hi


def test_paired_difference_drops_incomplete_pairs():
    a = np.array([0.8, np.nan, 0.7, 0.9, 0.6])
    b = np.array([0.7, 0.5, np.nan, 0.85, 0.58])
    keep = [0, 3, 4]
    assert paired_difference_ci(a, b) == bootstrap_ci(a[keep] - b[keep])


def test_paired_difference_rejects_bad_input():
    with pytest.raises(ValueError, match="equal lengths"):
        paired_difference_ci([1.0, 2.0], [1.0])
    with pytest.raises(ValueError, match="no complete pair"):
        paired_difference_ci([1.0, np.nan], [np.nan, 2.0])


def test_ratio_of_means_is_the_mean_gain_over_the_mean_gap_with_an_interval_around_it():
    rng = np.random.default_rng(3)
    gap = rng.uniform(0.15, 0.3, 12)
    gain = 0.5 * gap + rng.normal(0, 0.03, 12)
    r, lo, hi = ratio_of_means_ci(gain, gap, seed=1)
    assert r == pytest.approx(gain.mean() / gap.mean())
    assert lo < r < hi
    assert ratio_of_means_ci(gain, gap, seed=1) == (r, lo, hi)  # seeded


def test_ratio_of_means_resamples_the_pairs_together():
    """Gain proportional to the gap in every scene: every resample of whole scenes gives the same
    ratio (resampling gains and gaps independently would not)."""
    gap = np.array([0.1, 0.2, 0.3, 0.4, 0.25])
    r, lo, hi = ratio_of_means_ci(0.6 * gap, gap)
    assert r == pytest.approx(0.6)
    assert lo == pytest.approx(0.6) and hi == pytest.approx(0.6)


def test_ratio_of_means_rejects_bad_input():
    with pytest.raises(ValueError, match="equal lengths"):
        ratio_of_means_ci([1.0, 2.0], [1.0])
    with pytest.raises(ValueError, match="no complete pair"):
        ratio_of_means_ci([1.0, np.nan], [np.nan, 2.0])
    with pytest.raises(ValueError, match="mean of den is 0"):
        ratio_of_means_ci([1.0, 2.0], [1.0, -1.0])
    assert ratio_of_means_ci([0.0, 0.0, 0.0], [0.2, 0.3, 0.1]) == (0.0, 0.0, 0.0)


# ------------------------------------------------------------------------------------------------
# stratified t intervals, tests, Holm


def test_scene_kind():
    assert scene_kind("living_room_8001") == "living_room"
    assert scene_kind("office_7003") == "office"
    assert scene_kind("s0") == "s0" and scene_kind("room_a") == "room_a"


def test_unstratified_estimate_is_the_one_sample_t():
    x = np.random.default_rng(3).normal(0.5, 0.1, 9)
    est = stratified_estimate(x)
    assert est.mean == pytest.approx(x.mean()) and est.df == 8 and not est.stratified
    assert est.se == pytest.approx(x.std(ddof=1) / 3)
    ref = st.ttest_1samp(x, 0.45, alternative="greater")
    assert t_test_pvalue(est, 0.45, "greater") == pytest.approx(ref.pvalue)
    assert t_test_pvalue(est, 0.45, "less") == pytest.approx(1 - ref.pvalue)
    lo, hi = st.t.interval(0.95, 8, loc=x.mean(), scale=est.se)
    assert stratified_t_ci(x) == pytest.approx((x.mean(), lo, hi))


def test_stratified_estimate_uses_within_stratum_spread_and_welch_df():
    a, b = np.array([1.0, 2.0, 3.0]), np.array([10.0, 11.0, 13.0])
    est = stratified_estimate(np.r_[a, b], ["a"] * 3 + ["b"] * 3)
    assert est.stratified and est.mean == pytest.approx(np.r_[a, b].mean())
    # equal weights 1/2: var = (s_a^2/3 + s_b^2/3) / 4 (the same as Welch's SE of (a+b)/2)
    va, vb = a.var(ddof=1) / 3 / 4, b.var(ddof=1) / 3 / 4
    assert est.se == pytest.approx(np.sqrt(va + vb))
    assert est.df == pytest.approx((va + vb) ** 2 / (va**2 / 2 + vb**2 / 2))
    # a stratum with one value, or a single stratum: the plain t
    assert not stratified_estimate([1.0, 2.0, 4.0], ["a", "a", "b"]).stratified
    assert not stratified_estimate([1.0, 2.0, 4.0], ["a"] * 3).stratified
    with pytest.raises(ValueError, match="stratum labels"):
        stratified_estimate([1.0, 2.0], ["a"])
    with pytest.raises(ValueError, match="no values"):
        stratified_estimate([np.nan])


def test_degenerate_samples_and_their_tests():
    est = stratified_estimate([0.3, 0.3, 0.3])
    assert est.se == 0 and stratified_t_ci([0.3, 0.3, 0.3]) == (0.3, 0.3, 0.3)
    assert t_test_pvalue(est, 0.0, "greater") == 0.0 and t_test_pvalue(est, 0.0, "less") == 1.0
    assert t_test_pvalue(est, 0.3, "greater") == 1.0
    with pytest.raises(ValueError, match="alternative"):
        t_test_pvalue(est, 0.0, "two-sided")


def test_holm_matches_the_step_down_rule():
    p = [0.01, 0.04, 0.03, 0.005, np.nan]
    # sorted 0.005, 0.01, 0.03, 0.04 times 4, 3, 2, 1, made monotone
    np.testing.assert_allclose(holm(p), [0.03, 0.06, 0.06, 0.02, np.nan])
    assert holm([0.9, 0.8]).tolist() == [1.0, 1.0] and holm([0.2, 0.01]).tolist() == [0.2, 0.02]
    assert holm([]).size == 0 and np.isnan(holm([np.nan])).all()


@pytest.mark.parametrize("method", INTERVAL_METHODS)
def test_every_interval_method_brackets_the_mean(method):
    x = np.random.default_rng(11).normal(0.0, 1.0, 12)
    kinds = np.repeat(["a", "b", "c", "d"], 3)
    m, lo, hi = interval(x, kinds, method=method, n_resamples=500)
    assert m == pytest.approx(x.mean()) and lo < m < hi
    assert interval([0.5, 0.5], method=method) == (0.5, 0.5, 0.5)
    assert interval(x, kinds, method=method, n_resamples=500, seed=2) == interval(x, kinds, method=method,
                                                                                     n_resamples=500, seed=2)


def test_interval_refuses_unknown_methods():
    with pytest.raises(ValueError, match="method"):
        interval([1.0, 2.0], method="wald")


def test_ratio_lower_bound_is_fiellers_one_sided_t_bound():
    """The bound solves "one-sided t test of num - r * den at 5 % just rejects", is the ratio itself
    without noise, -inf when the denominator is not clearly positive, and covers 95 % of the time."""
    from semmatch.evaluate.stats import ratio_lower_bound

    den = np.array([0.20, 0.25, 0.18, 0.22, 0.30, 0.15])
    assert ratio_lower_bound(0.6 * den, den) == pytest.approx(0.6)
    rng = np.random.default_rng(3)
    num = 0.6 * den + rng.normal(0, 0.03, den.size)
    low = ratio_lower_bound(num, den)
    d = num - low * den
    assert d.mean() / (d.std(ddof=1) / np.sqrt(d.size)) == pytest.approx(st.t.ppf(0.95, d.size - 1), rel=1e-6)
    assert low < num.mean() / den.mean()
    assert ratio_lower_bound(num, rng.normal(0.0, 0.2, den.size) - 0.5) == float("-inf")
    hits = 0
    for _ in range(2000):  # 12 scenes, true ratio of means 0.6
        g = rng.normal(0.2, 0.06, 12)
        hits += ratio_lower_bound(0.6 * g + rng.normal(0, 0.05, 12), g) <= 0.6
    assert 0.93 <= hits / 2000 <= 0.97
    with pytest.raises(ValueError, match="at least 2"):
        ratio_lower_bound([0.1], [0.2])
