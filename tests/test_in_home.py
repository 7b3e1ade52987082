"""The in-home adaptation study (semmatch.experiments.in_home) on two tiny homes."""

from __future__ import annotations

import shutil

import numpy as np
import pandas as pd
import pytest
import yaml

from semmatch.experiments import in_home as ih


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    """Two tiny homes (training seed 3: no seed of the study's plan is generated here), a tiny
    network as both the unadapted and the across-homes network, a 2-step in-home recipe."""
    from semmatch.segment.training import make_config, train

    d = tmp_path_factory.mktemp("in_home")
    models = d / "models"
    cfg = make_config("smoke", out=str(models / "compact.pt"), kinds=("living_room",), train_seeds=(1,),
                      val_seeds=(501,), eval_seeds=(9001,), steps=2, eval_every=2, frames=2, val_frames=2,
                      progress=False)
    train(cfg)
    (models / "adapted").mkdir()
    shutil.copyfile(models / "compact.pt", models / "adapted" / "compact~3d-neighborhood.pt")
    plan = yaml.safe_load(ih.PLAN_PATH.read_text())
    plan["homes"] = {"kinds": ["bedroom", "living_room"], "seeds": [3]}
    plan["simulation"].update(n_frames_upper=6, n_frames_lower=5, image_width=64, image_height=48, camera_step=0.4)
    plan["adaptation"]["recipe"].update(steps=2, batch_size=4)
    (d / "plan.yaml").write_text(yaml.safe_dump(plan))
    per_home = ih.in_home_study(d / "data", plan_path=d / "plan.yaml", models=models, views_cache=d / "cache",
                                jobs=1, progress=False)
    return {"dir": d, "plan": ih.load_in_home_plan(d / "plan.yaml"), "per_home": per_home, "models": models}


def test_the_committed_plan_names_twelve_fresh_homes_and_the_cli_recipe():
    from semmatch.segment.adapt import AdaptRecipe

    plan = ih.load_in_home_plan()
    assert len(plan.homes) == 12 and len(set(plan.homes)) == 12
    assert plan.recipe == AdaptRecipe(seed=0)  # `semmatch adapt --home`'s defaults, not tuned on a home
    assert plan.primary == "mean_acc" and all(a == "in home" for a, _ in plan.comparisons)


def test_a_plan_with_an_unknown_arm_is_refused(tmp_path):
    plan = yaml.safe_load(ih.PLAN_PATH.read_text())
    plan["comparisons"] = [["in home", "oracle"]]
    (tmp_path / "p.yaml").write_text(yaml.safe_dump(plan))
    with pytest.raises(ValueError, match=r"unknown arms \['oracle'\]"):
        ih.load_in_home_plan(tmp_path / "p.yaml")


def test_every_home_scores_every_arm_on_the_second_tour(study):
    from semmatch.segment import load_model

    df = study["per_home"]
    assert sorted(df["home"].unique()) == ["bedroom_0003", "living_room_0003"]
    assert (df.groupby("home")["arm"].apply(tuple) == ih.ARMS).all()
    for m in ("mean_acc", "color_acc", "jaccard", "miou", "pixel_acc", "labelled"):
        assert df[m].between(0, 1).all(), m
    nets = df[df["arm"].isin(["unadapted", "across homes", "in home"])]
    assert (nets["labelled"] > 0.99).all()  # a network labels every pixel
    home = study["dir"] / "data" / "homes" / "bedroom_0003"
    first = np.loadtxt(home / "first" / "poses.txt", usecols=(1, 2, 3))
    second = np.loadtxt(home / "second" / "poses.txt", usecols=(1, 2, 3))
    assert not np.allclose(first, second)  # scored on another tour than the one adapted on
    rec = load_model(home / "in_home.pt").info["adapted"]
    assert rec["home"]["sequence"].endswith("first") and rec["map"]["path"].endswith("person.ply")
    assert rec["steps"] == 2 and rec["label_source"] == "3d-neighborhood"
    inh = df[df["arm"] == "in home"].iloc[0]
    assert 0 < inh["label_coverage"] <= 1 and inh["adapt_cpu_s"] > 0 and 0 < inh["finetune_s"] <= inh["adapt_s"]
    again = ih.in_home_study(study["dir"] / "data", plan_path=study["dir"] / "plan.yaml", models=study["models"],
                             views_cache=study["dir"] / "cache", homes=[("bedroom", 3)], jobs=1, progress=False)
    reused = again[again["arm"] == "in home"].iloc[0]  # the checkpoint of the first run: scored, not adapted again
    assert np.isnan(reused["adapt_s"]) and reused["finetune_s"] == inh["finetune_s"]
    pd.testing.assert_frame_equal(again[["arm", "mean_acc", "miou"]].reset_index(drop=True),
                                  df[df["home"] == "bedroom_0003"][["arm", "mean_acc", "miou"]].reset_index(drop=True))


def test_comparisons_are_paired_per_home_and_judged_by_the_plan(study, tmp_path):
    comps = ih.in_home_comparisons(study["per_home"], study["plan"])
    primary = comps[comps["role"] == "primary"]
    assert primary["comparison"].tolist() == ["in home - unadapted", "in home - across homes", "in home - transfer",
                                              "in home - fused"]
    assert set(comps["verdict"]) <= {"holds", "does not hold", "equivalent", "inconclusive"}
    wide = study["per_home"].pivot(index="home", columns="arm", values="mean_acc")
    assert primary["diff"].iloc[2] == pytest.approx((wide["in home"] - wide["transfer"]).mean())
    assert (primary["homes"] == 2).all()
    paths = ih.write_in_home_results(study["per_home"], comps, study["plan"], tmp_path / "fig", minutes=1.0)
    assert {p.name for p in paths} == {"in_home_per_home.csv", "in_home_per_home.md", "in_home_comparisons.csv",
                                       "in_home_comparisons.md", "in_home.png", "run.json"}
    pd.testing.assert_frame_equal(pd.read_csv(tmp_path / "fig" / "in_home_comparisons.csv"), comps,
                                  check_dtype=False, check_exact=False, atol=5e-5)  # save_table: 4 decimals
    assert (tmp_path / "fig" / "in_home.png").stat().st_size > 10_000


def test_a_home_folder_made_with_other_settings_is_not_reused(study, tmp_path):
    plan = yaml.safe_load((study["dir"] / "plan.yaml").read_text())
    plan["adaptation"]["recipe"]["steps"] = 3
    (tmp_path / "other.yaml").write_text(yaml.safe_dump(plan))
    with pytest.raises(ValueError, match=r"bedroom_0003: made with other settings \(recipe differ\)"):
        ih.in_home_study(study["dir"] / "data", plan_path=tmp_path / "other.yaml", models=study["models"],
                         views_cache=study["dir"] / "cache", homes=[("bedroom", 3)], progress=False)
    stray = study["dir"] / "data" / "homes" / "office_0003"
    stray.mkdir()
    (stray / "person.ply").write_text("not ours")
    with pytest.raises(ValueError, match="office_0003: holds files but no settings.json"):
        ih.in_home_study(study["dir"] / "data", plan_path=study["dir"] / "plan.yaml", models=study["models"],
                         views_cache=study["dir"] / "cache", homes=[("office", 3)], progress=False)
    assert (stray / "person.ply").read_text() == "not ours"


def test_the_command_refuses_a_plan_whose_homes_were_used(tmp_path, capsys):
    plan = yaml.safe_load(ih.PLAN_PATH.read_text())
    plan["homes"]["seeds"] = [3]  # a training scene of every profile
    (tmp_path / "p.yaml").write_text(yaml.safe_dump(plan))
    with pytest.raises(SystemExit) as e:
        ih.main(["--plan", str(tmp_path / "p.yaml"), "--data", str(tmp_path / "d"), "--figures", str(tmp_path / "f")])
    assert e.value.code == 2
    assert "3" in capsys.readouterr().err and not (tmp_path / "d").exists()
