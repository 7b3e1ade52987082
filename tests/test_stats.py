"""semmatch.stats: percentile bootstrap intervals of a mean and of a paired difference."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from semmatch.stats import bootstrap_ci, paired_difference_ci, ratio_of_means_ci


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
