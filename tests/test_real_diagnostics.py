"""The real-like chain's diagnostic arms: priors regenerated, arms paired per scene, Table 3's chain reproduced."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from conftest import noisy_scene_root

from semmatch.experiments.real import evaluate_real_like
from semmatch.experiments.real_diagnostics import (
    APPEARANCE_SEVERITY,
    ARMS,
    Arm,
    appearance_severity_on_validation,
    diagnostic_arms,
    drifted_prior,
    frames_kind,
    main,
    real_like_diagnostics,
)
from semmatch.experiments.real_diagnostics_tables import arm_differences, draw_spread, summarize_arms
from semmatch.io import read_sequence, read_tum
from semmatch.sim.appearance import write_heldout_recording

SCENE = "bedroom_0003"


@pytest.fixture(scope="module")
def tiny_root(tmp_path_factory):
    """A data root with one small evaluation scene (clean and Kinect-like noisy recordings)."""
    return noisy_scene_root(tmp_path_factory, "real_diag", 20)


def test_prior_draw_zero_is_the_recording_and_drift_scales_it(tiny_root, tmp_path):
    rec = tiny_root / "scenes" / "eval" / SCENE / "lower_noisy"
    true = read_tum(rec / "poses_gt.txt")[1]
    recorded = read_tum(rec / "poses.txt")[1]
    np.testing.assert_array_equal(drifted_prior(rec, true), recorded)  # the file itself
    (tmp_path / "copy").mkdir()
    (tmp_path / "copy" / "meta.json").write_text((rec / "meta.json").read_text())  # no poses.txt: regenerated
    np.testing.assert_allclose(drifted_prior(tmp_path / "copy", true), recorded, atol=1e-6)  # the file's rounding
    assert np.abs(drifted_prior(rec, true, draw=1) - recorded).max() > 1e-4  # another stream

    def max_error(p):
        return np.linalg.norm(p[:, :3, 3] - true[:, :3, 3], axis=1).max()

    jitter_only = drifted_prior(rec, true, drift=0.0)
    assert max_error(jitter_only) < 5 * 0.005 * np.sqrt(3)  # the per-frame jitter alone (sigma 5 mm)
    assert max_error(drifted_prior(rec, true, drift=4.0)) > max_error(drifted_prior(rec, true, drift=1.0))
    (tmp_path / "no_noise").mkdir()
    (tmp_path / "no_noise" / "meta.json").write_text(json.dumps({"frames": 3}))
    with pytest.raises(ValueError, match="no_noise.*noise"):
        drifted_prior(tmp_path / "no_noise", true)


def test_arms_and_their_bad_settings():
    arms = diagnostic_arms([0.0, 1.0, 2.0])
    assert [a.name for a in arms[:len(ARMS)]] == [a.name for a in ARMS]
    assert [(a.name, a.drift) for a in arms[len(ARMS):]] == [("chain", 0.0), ("chain", 2.0)]
    assert not Arm("x", "clean", "true").random and Arm("x", "noisy", "estimated").random
    with pytest.raises(ValueError, match="drift levels"):
        diagnostic_arms([-1.0])
    assert frames_kind("noisy") == ("noisy", 0.0) and frames_kind("heldout") == ("heldout", 1.0)
    assert frames_kind("heldout@0.25") == ("heldout", 0.25)
    for bad in ("noisy@0.5", "heldout@0", "heldout@2", "sunny"):
        with pytest.raises(ValueError, match="frames"):
            frames_kind(bad)


def test_study_reproduces_table3_chain_and_pairs_the_arms(tiny_root, tmp_path, oracle_network, monkeypatch):
    # the command line's settings (its test below then reuses these arms)
    kw = dict(voxel_size=0.04, registration_voxel=0.1, registration_restarts=3, prior_tolerance=(0.1, 10.0))
    arms = [ARMS[0], ARMS[1], ARMS[3], ARMS[4], ARMS[5], Arm("chain", "noisy", "estimated", drift=0.0)]
    res = real_like_diagnostics(tiny_root, networks=["noisy"], arms=arms, draws=2, progress=False, **kw)
    scores = res["scores"]
    # arms at true poses run once; the drift-0 chain once (sweep_draws); the others every draw
    draws = scores.groupby(["arm", "drift"])["draw"].nunique().to_dict()
    assert draws == {("clean, true poses", 1.0): 1, ("noisy, true poses", 1.0): 1, ("chain", 1.0): 2,
                     ("person visual-only", 1.0): 2, ("chain", 0.0): 1, ("held-out appearance, true poses", 1.0): 1}
    # the held-out look: the noisy recording's depth, labels and poses, other RGB
    looks = list((tiny_root / "real_diagnostics" / "appearance").glob(f"{SCENE}-*/lower-look*"))
    assert len(looks) == 1
    noisy, held = read_sequence(tiny_root / "scenes" / "eval" / SCENE / "lower_noisy"), read_sequence(looks[0])
    assert json.loads((looks[0] / "meta.json").read_text())["appearance"]["seed"] == 3
    for i in (0, len(noisy) - 1):
        a, b = noisy[i], held[i]
        np.testing.assert_array_equal(a.depth, b.depth)
        np.testing.assert_array_equal(noisy.read_labels(i), held.read_labels(i))
        np.testing.assert_array_equal(a.pose, b.pose)
        assert np.abs(a.rgb.astype(int) - b.rgb.astype(int)).mean() > 20
    # written again elsewhere: the same frames, and a killed writer's temporary folder is removed
    stale = tmp_path / ".again.999999999-x.partial"
    stale.mkdir()
    again = write_heldout_recording(tiny_root / "scenes" / "eval" / SCENE / "lower_noisy", tmp_path / "again")
    assert not stale.exists() and not list(tmp_path.glob(".again*"))
    np.testing.assert_array_equal(read_sequence(again)[1].rgb, held[1].rgb)
    assert set(zip(scores["model"], scores["method"])) == {
        ("ground truth", "3d-neighborhood"), ("noisy", "lower"), ("noisy", "3d-neighborhood"), ("noisy", "fused"),
        ("noisy", "upper")}
    assert scores[["jaccard", "sorensen", "color_acc", "mean_acc"]].apply(lambda c: c.between(0, 1)).all().all()
    # draw 0 of the chain is Table 3's chain (the full profile's: network rows only): the recorded prior,
    # RANSAC seed 0, the lower reference registered onto the network's map
    table, _, _ = evaluate_real_like(tiny_root, ["3d-neighborhood"], ["noisy"], include_ground_truth=False,
                                     progress=False, **kw)
    chain0 = scores[(scores["arm"] == "chain") & (scores["drift"] == 1.0) & (scores["draw"] == 0)
                    & (scores["model"] == "noisy")]
    a = chain0.set_index(["model", "method"])["mean_acc"].sort_index()
    b = table.set_index(["model", "method"])["mean_acc"].sort_index()
    pd.testing.assert_series_equal(a, b, check_exact=False, atol=1e-9)
    # the visual-only person: no prior row for the person; the robot keeps its prior (same draw: same poses)
    traj = res["trajectories"]
    vis = traj[traj["arm"] == "person visual-only"]
    assert set(vis.loc[vis["sequence"] == "upper", "poses"]) == {"estimated"}
    assert set(vis.loc[vis["sequence"] == "lower", "poses"]) == {"prior", "estimated"}
    assert traj[traj["arm"].str.contains("true poses")].empty
    # summaries
    summary = summarize_arms(res)
    assert {"mean_acc_lo", "mean_acc_hi", "draw_sd", "ate_lower_m", "reg_trans_err_median_m"} <= set(summary.columns)
    row = summary[(summary["arm"] == "chain") & (summary["drift"] == 1.0) & (summary["method"] == "lower")].iloc[0]
    assert row["draws"] == 2 and row["scenes"] == 1
    spread = draw_spread(scores)
    assert np.isnan(spread.loc[spread["arm"] == "clean, true poses", "draw_sd"]).all()
    diffs, contrasts = arm_differences(res)
    assert {"sensor noise (true poses)", "estimated poses (noisy frames)", "person tracked visually only",
            "held-out appearance (true poses)"} <= set(diffs["effect"])
    one = diffs[(diffs["effect"] == "sensor noise (true poses)") & (diffs["model"] == "noisy")
                & (diffs["method"] == "lower")].iloc[0]
    per = scores.set_index(["arm", "model", "method"])["mean_acc"]
    assert one["diff"] == pytest.approx(per["noisy, true poses", "noisy", "lower"]
                                        - per["clean, true poses", "noisy", "lower"])
    assert set(contrasts["contrast"]) == {"transfer - lower (C15)", "transfer - upper (C16)", "fused - lower"}

    # a second run reuses every arm's result.json (nothing is recomputed)
    import semmatch.experiments.real as real

    monkeypatch.setattr(real, "chain_from_poses", lambda *a, **k: pytest.fail("recomputed"))
    again = real_like_diagnostics(tiny_root, networks=["noisy"], arms=arms, draws=2, progress=False, **kw)
    pd.testing.assert_frame_equal(again["scores"], scores)
    assert not res["tasks"]["reused"].any() and again["tasks"]["reused"].all() and len(again["tasks"]) == 8
    # another checkpoint (or other recordings) is another input: nothing cached is reused
    (tiny_root / "models").mkdir(exist_ok=True)
    (tiny_root / "models" / "noisy.pt").write_bytes(b"another network")
    try:
        with pytest.raises(pytest.fail.Exception, match="recomputed"):
            real_like_diagnostics(tiny_root, networks=["noisy"], arms=arms[:1], draws=1, progress=False, **kw)
    finally:
        (tiny_root / "models" / "noisy.pt").unlink()
    # a change to the look's code: the held-out arm renders, predicts and scores again; the others are reused
    import semmatch.experiments.real_diagnostics as rd

    monkeypatch.setattr(rd, "look_digest", lambda: "0ther000")
    held_arm = [a for a in arms if a.frames.startswith("heldout")]
    with pytest.raises(pytest.fail.Exception, match="recomputed"):
        real_like_diagnostics(tiny_root, networks=["noisy"], arms=held_arm, draws=1, progress=False, **kw)
    assert list((tiny_root / "real_diagnostics" / "appearance").glob(f"{SCENE}-*/lower-look0ther000"))
    noisy_arm = [a for a in arms if a.frames == "noisy" and a.poses == "true"]
    assert real_like_diagnostics(tiny_root, networks=["noisy"], arms=noisy_arm, draws=1, progress=False,
                                 **kw)["tasks"]["reused"].all()


def test_cli_writes_the_tables_and_figure(tiny_root, tmp_path, oracle_network, capsys):
    figures = tmp_path / "fig"
    assert main(["--data", str(tiny_root), "--figures", str(figures), "--networks", "noisy", "--draws", "1",
                 "--drift-levels", "1", "2"]) == 0
    for name in ("arms", "differences", "contrasts", "draw_spread", "per_scene", "trajectories", "registration"):
        assert (figures / f"real_diagnostics_{name}.csv").is_file() and (figures / f"real_diagnostics_{name}.md").is_file()
    assert (figures / "real_diagnostics.png").stat().st_size > 10_000
    run = json.loads((figures / "run.json").read_text())
    assert run["scenes"] == 1 and run["drift_levels"] == [1.0, 2.0] and run["tasks"] == 10 and run["tasks_reused"] in (0, 5)  # 5 when the study test ran first
    gap = pd.read_csv(figures / "real_diagnostics_appearance_gap.csv").set_index(["model", "method"])
    assert gap.loc[("noisy", "lower"), "paper_drop"] == pytest.approx(0.766 - 0.590, abs=1e-4)  # the CSV's 4 places
    assert np.isnan(gap.loc[("ground truth", "3d-neighborhood"), "paper_drop"])
    assert gap.loc[("noisy", "lower"), "drop x1"] == pytest.approx(gap.loc[("noisy", "lower"), "clean, true poses"]
                                                                  - gap.loc[("noisy", "lower"), "held-out appearance, true poses"],
                                                                  abs=2e-4)
    assert f"drop x{APPEARANCE_SEVERITY:g}" in gap.columns
    diffs = pd.read_csv(figures / "real_diagnostics_differences.csv")
    assert f"held-out appearance x{APPEARANCE_SEVERITY:g} (chain)" in set(diffs["effect"])
    assert (figures / "real_diagnostics_appearance_gap.png").stat().st_size > 10_000
    with pytest.raises(SystemExit):
        main(["--data", str(tmp_path / "nowhere")])
    assert "no evaluation scenes" in capsys.readouterr().err
    for bad, msg in ((["--methods", "dbscan"], "need 3d-neighborhood"), (["--scenes", "attic_0001"], "no evaluation scene"),
                     (["--draws", "0"], "draws must be >= 1")):
        with pytest.raises(SystemExit):
            main(["--data", str(tiny_root), "--figures", str(figures), *bad])
        assert msg in capsys.readouterr().err


def test_the_appearance_severity_is_chosen_on_validation_scenes(tmp_path, oracle_network, capsys):
    from semmatch.io.geometry import DEFAULT_INTRINSICS
    from semmatch.sim import NoiseConfig, generate_dataset

    root = tmp_path / "data"
    generate_dataset(root / "scenes", train_seeds=[], val_seeds=[5], eval_seeds=[3], kinds=["bedroom"],
                     n_frames_upper=8, n_frames_lower=8, heights_sweep=None,
                     intrinsics=DEFAULT_INTRINSICS.scaled(160, 120), noise=NoiseConfig.kinect(3), progress=False)
    table, chosen = appearance_severity_on_validation(root, "noisy", levels=(0.5, 1.0), progress=False)
    assert list(table["frames"]) == ["clean", "noisy", "0.5", "1"]
    assert table.loc[0, "kept"] == pytest.approx(1.0) and table["scenes"].eq(1).all()
    assert table["chosen"].sum() == 1 and chosen in (0.5, 1.0)
    assert table.loc[table["chosen"], "frames"].item() == f"{chosen:g}"
    assert [p.name for p in (root / "real_diagnostics").glob("appearance_validation-look*")]  # keyed by the look
    assert main(["--data", str(root), "--figures", str(tmp_path / "fig"), "--networks", "noisy", "--choose-severity"]) == 0
    assert (tmp_path / "fig" / "appearance_severity_validation.md").is_file()
    assert "chosen severity" in capsys.readouterr().out
