"""Intervals over networks and scenes (semmatch.evaluate.stats) and their coverage simulation."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from semmatch.evaluate.stats import (
    bootstrap_ci,
    grid_bootstrap,
    network_scene_grid,
    stratified_t_ci,
    two_component_t_ci,
    two_level_bootstrap,
)
from semmatch.experiments.two_level_coverage import (
    METHODS,
    simulate_grid,
    two_level_coverage_study,
    two_level_coverage_summary,
)

KINDS = ("living_room", "bedroom", "office", "apartment")


def _long(grid: np.ndarray) -> tuple[np.ndarray, list[str], list[str], list[str]]:
    """Long form of a networks x scenes grid whose scenes cycle through the four kinds."""
    n_net, n_sc = grid.shape
    scenes = [f"{KINDS[j % 4]}_{8001 + j}" for j in range(n_sc)]
    nets = [f"s{i}" for i in range(n_net) for _ in range(n_sc)]
    return grid.ravel(), nets, scenes * n_net, [s.rsplit("_", 1)[0] for s in scenes] * n_net


def test_grid_from_long_form_drops_incomplete_scenes_and_checks_input():
    grid, strata = network_scene_grid([1.0, 2.0, 3.0, np.nan], ["a", "a", "b", "b"], ["x_1", "y_1", "x_1", "y_1"],
                                      ["x", "y", "x", "y"])
    assert grid.tolist() == [[1.0], [3.0]] and strata.tolist() == ["x"]
    with pytest.raises(ValueError, match="more than once"):
        network_scene_grid([1, 2], ["a", "a"], ["x", "x"])
    with pytest.raises(ValueError, match="several strata"):
        network_scene_grid([1, 2], ["a", "b"], ["x", "x"], ["k1", "k2"])
    with pytest.raises(ValueError, match="equal lengths"):
        network_scene_grid([1, 2], ["a"], ["x", "y"])
    with pytest.raises(ValueError, match="no scene has a value for every network"):
        network_scene_grid([1, np.nan], ["a", "b"], ["x", "x"])


def test_degenerate_grid_gives_zero_width_and_bad_levels_are_refused():
    v, n, s, g = _long(np.full((3, 8), 0.25))
    r = two_level_bootstrap(v, n, s, g)
    assert (r.mean, r.lo, r.hi, r.lower, r.upper) == (0.25,) * 5 and (r.n_networks, r.n_scenes) == (3, 8)
    assert two_component_t_ci(v, n, s).lo == 0.25
    with pytest.raises(ValueError, match="confidence"):
        two_level_bootstrap(v, n, s, confidence=1.0)
    with pytest.raises(ValueError, match="confidence"):
        two_component_t_ci(v, n, s, confidence=0.0)
    with pytest.raises(ValueError, match="without NaN"):
        grid_bootstrap(np.array([[np.nan, 1.0]]))


def test_one_network_reduces_to_the_scene_bootstrap_and_the_plain_t():
    x = np.random.default_rng(3).normal(0.02, 0.05, 24)
    v, n, s, _ = _long(x[None, :])
    r = two_level_bootstrap(v, n, s, n_resamples=20000, seed=1)
    _, lo, hi = bootstrap_ci(x, n_resamples=20000, seed=2)
    assert r.mean == pytest.approx(x.mean()) and r.lo == pytest.approx(lo, abs=0.003) and r.hi == pytest.approx(hi, abs=0.003)
    assert r.lo < r.lower < r.mean < r.upper < r.hi
    t = two_component_t_ci(v, n, s)
    assert (t.mean, t.lo, t.hi) == pytest.approx(stratified_t_ci(x))
    assert t.lower == pytest.approx(stratified_t_ci(x, confidence=0.90)[1])


def test_network_spread_widens_the_two_level_interval_only():
    rng = np.random.default_rng(5)
    grid = rng.normal(0.0, 0.02, (3, 24)) + np.array([[-0.06], [0.0], [0.06]])
    v, n, s, g = _long(grid)
    one = two_level_bootstrap(v, n, s, g, resample_networks=False, n_resamples=4000)
    two = two_level_bootstrap(v, n, s, g, n_resamples=4000)
    assert two.hi - two.lo > 3 * (one.hi - one.lo)
    # the bootstrap's network draws: the mean's spread is about sqrt((N-1)/N) x the SD of the network means / sqrt(N)
    sd_means = np.sqrt(2 / 3) * grid.mean(axis=1).std(ddof=1) / np.sqrt(3)
    assert (two.hi - two.lo) / 3.92 == pytest.approx(sd_means, rel=0.25)
    t = two_component_t_ci(v, n, s)
    assert t.hi - t.lo > two.hi - two.lo  # t with ~2 df: wider than the bootstrap's percentiles


def test_scenes_are_resampled_within_their_kinds():
    # every scene of a kind equal: within-kind resampling cannot move the mean, a pooled one can
    grid = np.tile(np.repeat([0.0, 0.1, 0.2, 0.3], 3), (2, 1))
    kinds = np.repeat(KINDS, 3)
    within = grid_bootstrap(grid, kinds, resample_networks=False, n_resamples=500)
    pooled = grid_bootstrap(grid, None, resample_networks=False, n_resamples=500)
    assert within.lo == pytest.approx(0.15) and within.hi == pytest.approx(0.15) and pooled.hi - pooled.lo > 0.05


def test_coverage_simulation_small_case():
    comp = {"toy": pd.DataFrame({"kind": np.repeat(KINDS, 3), "diff": np.random.default_rng(0).normal(0.0, 0.03, 12)})}
    grid, kinds = simulate_grid(comp["toy"], network_sd=0.05, interaction_sd=0.01, n_networks=3, scenes_per_kind=6,
                                rng=np.random.default_rng(1))
    assert grid.shape == (3, 24) and sorted(set(kinds)) == sorted(KINDS)
    study = two_level_coverage_study(comp, network_sds=(0.0, 0.08), reps=60, n_resamples=300, progress=False)
    assert len(study) == 2 * len(METHODS) and study["coverage"].between(0, 1).all()
    cov = study.set_index(["network_sd", "method"])["coverage"]
    assert cov[(0.0, "two-component-t")] >= 0.85
    # a network effect larger than the scene noise: one network's t over scenes misses the truth
    assert cov[(0.08, "v1-t")] < 0.6 < cov[(0.08, "two-component-t")]
    summary = two_level_coverage_summary(study)
    assert list(summary.columns[:2]) == ["network_sd", "method"] and len(summary) == 2 * len(METHODS)
    with pytest.raises(ValueError, match="n_networks"):
        two_level_coverage_study(comp, n_networks=0, reps=1, progress=False)
