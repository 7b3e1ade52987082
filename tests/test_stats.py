"""semmatch.stats: percentile bootstrap intervals of a mean and of a paired difference."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from semmatch.stats import bootstrap_ci, paired_difference_ci


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
