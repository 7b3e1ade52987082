"""The "when transfer pays" study: its crossover estimator, its bootstrap, its grid and its tables."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from semmatch.evaluate.stats import interval
from semmatch.experiments import when_transfer_pays as wtp

HEIGHTS = (0.1, 0.2, 0.3, 0.4, 0.6, 0.8)
KINDS = ["living_room", "bedroom", "office", "apartment"]


def _scenes(per_kind: int) -> list[str]:
    return [f"{k}_{9500 + i:04d}" for k in KINDS for i in range(per_kind)]


def _linear_curves(h0: float, slope: float, *, scenes: int, networks: int = 1, sd: float = 0.02,
                   net_sd: float = 0.0, seed: int = 0) -> np.ndarray:
    """(networks, scenes, heights): slope * (h0 - h) + a scene offset + a network offset + noise."""
    rng = np.random.default_rng(seed)
    h = np.asarray(HEIGHTS)
    scene = rng.normal(0, sd, (1, scenes, 1))
    net = rng.normal(0, net_sd, (networks, 1, 1))
    noise = rng.normal(0, sd / 2, (networks, scenes, h.size))
    return slope * (h0 - h)[None, None, :] + scene + net + noise


def test_a_known_crossover_is_recovered_with_an_interval_covering_it():
    d = _linear_curves(0.45, 0.3, scenes=12)
    kinds = [k for k in KINDS for _ in range(3)]
    e = wtp.crossover_estimate(HEIGHTS, d, kinds, n_resamples=500, seed=1)
    assert e["crossover"] == pytest.approx(0.45, abs=0.05)
    assert e["lo"] <= 0.45 <= e["hi"] and e["hi"] - e["lo"] < 0.3
    assert e["direction"] == "pays below" and e["share_crossing"] > 0.95
    assert e["band_lo"].shape == e["band_hi"].shape == (len(HEIGHTS),)
    assert np.all(e["band_lo"] <= e["mean"]) and np.all(e["mean"] <= e["band_hi"])
    # the other way round: the curve rises through zero
    up = wtp.crossover_estimate(HEIGHTS, -d, kinds, n_resamples=200)
    assert up["direction"] == "pays above" and up["crossover"] == pytest.approx(e["crossover"])


def test_the_crossing_is_interpolated_linearly_and_a_zero_on_the_grid_is_a_crossing():
    assert wtp.crossing_point([0.1, 0.2, 0.3], [0.03, 0.01, -0.01]) == pytest.approx(0.25)
    assert wtp.crossing_point([0.1, 0.2, 0.3], [0.03, 0.0, -0.01]) == pytest.approx(0.2)
    assert wtp.crossing_point([0.1, 0.2], [-0.02, 0.06]) == pytest.approx(0.125)


def test_no_crossover_is_a_result_with_the_side_transfer_pays_on():
    kinds = [k for k in KINDS for _ in range(3)]
    d = _linear_curves(1.5, 0.1, scenes=12, sd=0.005)  # positive everywhere, falling towards 0.8
    e = wtp.crossover_estimate(HEIGHTS, d, kinds, n_resamples=300)
    assert np.isnan(e["crossover"]) and e["direction"] == "pays at every height"
    assert e["share_crossing"] == 0.0 and e["lo"] == e["hi"] == np.inf  # it would cross above the grid
    e = wtp.crossover_estimate(HEIGHTS, -d, kinds, n_resamples=300)
    assert e["direction"] == "pays at no height" and e["hi"] == np.inf
    assert wtp.beyond_grid(HEIGHTS, np.linspace(0.01, 0.2, 6)) == -np.inf  # nearer zero at the low end
    with pytest.raises(ValueError, match="changes sign"):
        wtp.beyond_grid([0.1, 0.2], [0.1, -0.1])
    # the table writes an open bound
    assert wtp._fmt_point(np.inf, HEIGHTS) == "> 0.8" and wtp._fmt_point(-np.inf, HEIGHTS) == "< 0.1"


def test_with_several_sign_changes_the_first_from_below_is_taken():
    h = [0.1, 0.2, 0.3, 0.4, 0.6, 0.8]
    v = [0.04, -0.02, -0.01, 0.03, 0.02, -0.05]  # + - + - : three sign changes
    assert wtp.crossing_point(h, v) == pytest.approx(0.1 + 0.04 * 0.1 / 0.06)
    assert wtp.crossing_point(h, [-x for x in v]) == pytest.approx(wtp.crossing_point(h, v))
    # a monotonic curve crosses once, wherever it is scanned from
    mono = np.linspace(0.05, -0.05, 6)
    assert wtp.crossing_point(h, mono) == pytest.approx(np.interp(0.0, mono[::-1], np.asarray(h)[::-1]))


@pytest.mark.parametrize("grid, values, match", [
    ([0.1], [0.1], "length >= 2"), ([0.1, 0.2], [0.1], "equal length"), ([0.2, 0.1], [0.1, 0.2], "increase"),
    ([0.1, 0.2], [0.1, np.nan], "NaN"),
])
def test_bad_curves_are_refused(grid, values, match):
    with pytest.raises(ValueError, match=match):
        wtp.crossing_point(grid, values)


def test_the_scene_level_is_the_stratified_percentile_bootstrap_of_the_stats_module():
    """One network and one grid point: the resampled means give exactly stats.interval's bounds."""
    rng = np.random.default_rng(3)
    x = rng.normal(0.02, 0.05, 12)
    kinds = [k for k in KINDS for _ in range(3)]
    means = wtp.resample_means(x[None, :, None], kinds, n_resamples=999, seed=5)[:, 0]
    _, lo, hi = interval(x, kinds, method="stratified-percentile", n_resamples=999, seed=5)
    assert np.quantile(means, [0.025, 0.975]) == pytest.approx([lo, hi])
    # every point of a resample uses the same scenes: a constant shift moves every resampled mean alike
    two = wtp.resample_means(np.stack([x, x + 1.0], axis=1)[None], kinds, n_resamples=50, seed=2)
    assert two[:, 1] - two[:, 0] == pytest.approx(np.ones(50))


def test_the_networks_level_can_be_switched_on_and_widens_the_interval():
    kinds = [k for k in KINDS for _ in range(3)]
    d = _linear_curves(0.45, 0.3, scenes=12, networks=3, net_sd=0.03, seed=4)
    on = wtp.resample_means(d, kinds, networks_level=True, n_resamples=800, seed=0)
    off = wtp.resample_means(d, kinds, networks_level=False, n_resamples=800, seed=0)
    assert on.shape == off.shape == (800, len(HEIGHTS))
    assert np.all(on.std(axis=0) > off.std(axis=0))
    assert off.mean(axis=0) == pytest.approx(d.mean(axis=(0, 1)), abs=0.01)
    with pytest.raises(ValueError, match="kinds"):
        wtp.resample_means(d, kinds[:5])
    with pytest.raises(ValueError, match="NaN"):
        wtp.resample_means(np.full((1, 2, 2), np.nan), ["a", "b"])


def test_the_committed_grid_is_the_declared_design():
    from semmatch.experiments.appearance_severity import APPEARANCE_SEVERITY

    g = wtp.load_grid()
    assert g.heights == HEIGHTS and g.reference_height == 0.2 and g.tilts_deg == (0.0, 20.0)
    assert g.default_tilt_deg == 20.0 and g.cameras == ("robot", "both") and g.coverage == (0.25, 0.5, 1.0)
    assert g.severity == APPEARANCE_SEVERITY and g.measure == "mean_acc"
    assert g.secondary_methods == ("3d-neighborhood", "fused") and g.fused_base == "3d-neighborhood"
    names = [a.name for a in wtp.study_arms(g)]
    assert names == [f"height {h:g}" for h in HEIGHTS] + ["tilt 0", "look robot", "look both", "coverage 0.25",
                                                         "coverage 0.5"]
    arms = {a.name: a for a in wtp.study_arms(g)}
    # arms with the same camera share the robot's frames; the look arms differ in the person's map only
    assert arms["coverage 0.25"].robot_key == arms["height 0.2"].robot_key
    assert arms["look robot"].robot_key == arms["look both"].robot_key != arms["height 0.2"].robot_key
    assert arms["look robot"].person_key == (False, 1.0) and arms["look both"].person_key == (True, 1.0)


def test_a_bad_grid_is_refused_naming_the_file(tmp_path):
    text = wtp.GRID_PATH.read_text()
    for old, new, match in (("heights: [0.1, 0.2,", "heights: [0.2, 0.1,", "increasing"),
                            ("cameras: [robot, both]", "cameras: [robot, tripod]", "tripod"),
                            ("coverage: [0.25,", "coverage: [1.5,", "coverage"),
                            ("reference_height: 0.2", "reference_height: 0.25", "reference_height"),
                            ("measure: mean_acc", "measure: speed", "measure"),
                            ("fused_base: 3d-neighborhood", "fused_base: 4d", "method"),
                            ("secondary_methods: [3d-neighborhood,", "secondary_methods: [3d-slicer,", "secondary")):
        bad = tmp_path / "grid.yaml"
        bad.write_text(text.replace(old, new))
        with pytest.raises(ValueError, match=match) as e:
            wtp.load_grid(bad)
        assert str(bad) in str(e.value)


def test_scenes_of_a_split():
    assert wtp.study_scenes([8101], "eval")[:2] == [("living_room", 8101), ("bedroom", 8101)]
    assert wtp.study_scenes([502, 508], "val") == [("bedroom", 502), ("apartment", 508)]
    with pytest.raises(ValueError, match="not validation seeds"):
        wtp.study_scenes([7001], "val")


def _per_scene(grid) -> pd.DataFrame:
    """A synthetic per-scene table of the study's shape: transfer - lower = 0.3 (0.45 - h), + per arm."""
    rng = np.random.default_rng(0)
    rows = []
    for s in _scenes(2):
        for net in ("a", "b"):
            for arm in wtp.study_arms(grid):
                low = 0.7 + rng.normal(0, 0.01)
                rows.append(dict(scene=s, kind=s.rsplit("_", 1)[0], network=net, arm=arm.name, factor=arm.factor,
                                 height=arm.height, tilt_deg=arm.tilt_deg, look=arm.look, coverage=arm.coverage,
                                 method="lower", mean_acc=low))
                for m in wtp.arm_methods(grid, arm):
                    shift = -0.1 if arm.name == "look both" else 0.0
                    rows.append({**rows[-1], "method": m,
                                 "mean_acc": low + 0.3 * (0.45 - arm.height) + shift + rng.normal(0, 0.01)})
    return pd.DataFrame(rows)


def test_tables_and_figure_from_a_per_scene_table(tmp_path):
    from dataclasses import replace

    grid = replace(wtp.load_grid(), n_resamples=200)
    diffs = wtp.difference_table(_per_scene(grid), "mean_acc")
    assert len(diffs) == 8 * 2 * sum(len(wtp.arm_methods(grid, a)) for a in wtp.study_arms(grid))
    table, est = wtp.crossover_table(diffs, grid)
    assert list(table["method"]) == list(grid.methods)
    assert all(abs(float(c) - 0.45) < 0.05 for c in table["crossover"])
    assert set(table["networks"]) == {2} and set(table["scenes"]) == {8}
    arms = wtp.arms_table(diffs, grid)
    look = arms[(arms["arm"] == "look both") & (arms["method"] == "fused")].iloc[0]
    assert look["change"] == pytest.approx(-0.1, abs=0.02) and look["change_hi"] < 0
    assert arms[arms["factor"] == "height"]["change"].isna().all()
    assert set(arms[arms["factor"] != "height"]["method"]) == set(grid.secondary_methods)
    assert len(arms[arms["method"] == "dbscan"]) == len(grid.heights)
    png = wtp.plot_crossover(est, grid, tmp_path / "f.png", title="synthetic")
    assert png.is_file() and png.stat().st_size > 10_000


def test_make_confirm_runs_the_study_on_the_run_scenes_after_the_verdicts(tmp_path, monkeypatch):
    """The confirm plumbing (nothing real runs): ``make confirm`` passes ``--when-transfer-pays``, and
    ``run_confirm`` then calls the study on every kind of every seed, with the run's data root."""
    import re
    import subprocess

    import semmatch.experiments.claims as claims
    from semmatch.experiments import confirm
    from semmatch.experiments.pipeline import ROOT

    dry = subprocess.run(["make", "-n", "confirm", "SEEDS=9931 9932"], cwd=ROOT, capture_output=True, text=True,
                         check=True).stdout
    assert re.search(r"-m semmatch.experiments confirm --seeds 9931 9932 .*--when-transfer-pays", dry)
    order, seen = [], {}
    monkeypatch.setattr(confirm, "run_notebook", lambda nb, profile, **kw: order.append(nb))
    monkeypatch.setattr(claims, "judge_figures", lambda figures, **kw: order.append("verdicts"))

    def fake_study(data_root, figures, scenes, **kw):
        order.append("when_transfer_pays")
        seen.update(kw, data_root=Path(data_root), figures=Path(figures), scenes=list(scenes))

    monkeypatch.setattr(wtp, "run_when_transfer_pays", fake_study)
    record = confirm.run_confirm([9931, 9932], name="wtp", out_root=tmp_path, when_transfer_pays=True)
    assert order[-2:] == ["verdicts", "when_transfer_pays"] and "01_simulate" in order
    assert seen["scenes"] == [(k, s) for s in (9931, 9932) for k in KINDS] and seen["split"] == "eval"
    assert seen["data_root"] == tmp_path / "data" / "confirm" / "wtp"
    assert seen["figures"] == tmp_path / "figures" / "confirm" / "wtp" / "when_transfer_pays"
    assert "when_transfer_pays" in record["wall_seconds"]
    order.clear()
    assert "when_transfer_pays" not in confirm.run_confirm([9933], name="plain", out_root=tmp_path)["wall_seconds"]
    assert "when_transfer_pays" not in order


@pytest.mark.parametrize("args, match", [
    (["--split", "val", "--seeds", "7001"], "not validation seeds"),
    (["--seeds", "1"], "seed 1 is a training seed"),
])
def test_the_command_refuses_seeds_it_may_not_generate_before_any_work(tmp_path, capsys, args, match):
    with pytest.raises(SystemExit) as e:
        wtp.main([*args, "--out", str(tmp_path / "out"), "--data", str(tmp_path)])
    assert e.value.code == 2 and match in capsys.readouterr().err
    assert not (tmp_path / "out").exists() and not (tmp_path / "when_transfer_pays").exists()


def test_the_command_needs_the_grids_networks(tmp_path, capsys):
    with pytest.raises(SystemExit):
        wtp.main(["--split", "val", "--seeds", "501", "--out", str(tmp_path / "out"), "--data", str(tmp_path)])
    assert "compact.pt: no such network" in capsys.readouterr().err
