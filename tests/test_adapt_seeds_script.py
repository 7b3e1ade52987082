"""scripts/adapt_seeds.py: the interval over fine-tuning seeds and scenes together."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np

_spec = importlib.util.spec_from_file_location("adapt_seeds", Path(__file__).parents[1] / "scripts" / "adapt_seeds.py")
adapt_seeds = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(adapt_seeds)


def test_two_way_interval_is_exact_without_spread_and_widens_with_seed_noise():
    gap = np.tile(np.linspace(0.1, 0.3, 12), (3, 1))
    est, lo, hi = adapt_seeds.two_way_ratio_ci(0.6 * gap, gap, n_resamples=500)
    assert est == lo == hi or np.isclose([est, lo, hi], 0.6).all()
    rng = np.random.default_rng(0)
    scene_only = 0.6 * gap + rng.normal(0, 0.02, gap.shape[1])  # the same noise for every seed
    noisy = scene_only + rng.normal(0, 0.05, (3, 1))  # plus a shift per seed
    w1 = np.subtract(*adapt_seeds.two_way_ratio_ci(scene_only, gap, n_resamples=2000)[2:0:-1])
    w2 = np.subtract(*adapt_seeds.two_way_ratio_ci(noisy, gap, n_resamples=2000)[2:0:-1])
    assert 0 < w1 < w2  # seed-to-seed differences widen the interval


def test_two_way_interval_covers_the_true_share_in_most_simulated_studies():
    rng = np.random.default_rng(1)
    hits = 0
    for _ in range(60):
        gap = rng.uniform(0.1, 0.3, 12)
        gain = 0.5 * gap + rng.normal(0, 0.03, 12) + rng.normal(0, 0.02, (3, 1))
        _, lo, hi = adapt_seeds.two_way_ratio_ci(gain, np.tile(gap, (3, 1)), n_resamples=400)
        hits += lo <= 0.5 <= hi
    assert hits >= 45  # a percentile bootstrap over 3 seeds undercovers somewhat; not badly


def test_summarize_bounds_the_mean_over_seeds(tmp_path):
    """``summarize``: per-seed shares, the two-way interval and stage 09's one-sided bounds of the seed mean."""
    import argparse

    import pandas as pd

    from semmatch.experiments.adapt import gap_bounds

    rng = np.random.default_rng(3)
    rows, gaps = [], []
    for seed in (0, 1, 2):
        for i in range(12):
            scene = f"office_{7000 + i}"
            lo, hi = rng.uniform(0.3, 0.4), rng.uniform(0.6, 0.7)
            gain = (hi - lo) * (0.5 + 0.05 * seed) + rng.normal(0, 0.01)
            rows += [dict(model="compact", scene=scene, height=0.2, miou=lo, seed=seed),
                     dict(model="compact", scene=scene, height=1.6, miou=hi, seed=seed),
                     dict(model="compact~src", scene=scene, height=0.2, miou=lo + gain, seed=seed),
                     dict(model="compact~src", scene=scene, height=1.6, miou=hi - 0.01, seed=seed)]
        gaps += [dict(source="none (unadapted)", gap_closed=0.0, seed=seed),
                 dict(source="src", gap_closed=0.5 + 0.05 * seed, seed=seed)]
    per_scene = pd.DataFrame(rows)
    per_scene.to_csv(tmp_path / "adapt_seeds_height_per_scene.csv", index=False)
    pd.DataFrame(gaps).to_csv(tmp_path / "adapt_seeds_gap.csv", index=False)
    adapt_seeds.summarize(argparse.Namespace(figures=tmp_path), {"network": "compact"})
    spread = pd.read_csv(tmp_path / "adapt_seeds_spread.csv").iloc[0]
    assert spread["seeds"] == 3 and spread["scenes"] == 12 and spread["gap_closed_per_seed"] == "50% / 55% / 60%"
    mean = per_scene.groupby(["model", "scene", "height"], sort=False)["miou"].mean().reset_index()
    expected = gap_bounds(mean, "compact").iloc[0]
    assert np.isclose(spread["gap_closed_lower"], expected["gap_closed_lower"], atol=1e-4)
    assert 0.4 < spread["gap_closed_lower"] < spread["gap_closed"] < 0.6 and not spread["clears_60"]
    assert np.isclose(spread["change_high"], -0.01, atol=1e-4) and spread["scenes_losing"] == 0
    assert (tmp_path / "adapt_seeds.png").is_file()
