"""Confirmatory runs (``make confirm``): seed refusal, parameters, shipped networks, a smoke-sized run."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
import yaml

from semmatch.experiments import confirm, pipeline
from semmatch.experiments.protocol import RETIRED_SEEDS, check_confirm_seeds

ROOT = Path(__file__).resolve().parents[1]
PROFILES = yaml.safe_load((ROOT / "params.yaml").read_text())["profiles"]


@pytest.mark.parametrize("seed, split", [
    (PROFILES["full"]["common"]["eval_seeds"][0], "development evaluation seed"),
    (PROFILES["full"]["common"]["train_seeds"][0], "training seed"),
    (PROFILES["full"]["common"]["val_seeds"][-1], "validation seed"),
    (PROFILES["full"]["common"]["dev_seeds"][0], "development seed"),
    (PROFILES["smoke"]["common"]["eval_seeds"][0], "development evaluation seed (profile smoke)"),
    (9001, "former development evaluation seed"),
])
def test_a_used_seed_is_refused_naming_the_seed_and_its_split(seed, split):
    with pytest.raises(ValueError, match=re.escape(f"seed {seed} is a {split}")):
        check_confirm_seeds([9101, seed], PROFILES)
    assert 9001 in RETIRED_SEEDS


def test_fresh_and_reserved_seeds_are_accepted_and_bad_lists_refused():
    # the large profile's evaluation seeds are reserved, never generated: not development scenes
    reserved = PROFILES["large"]["common"]["eval_seeds"][0]
    assert check_confirm_seeds(["9101", 9102, reserved], PROFILES) == [9101, 9102, reserved]
    for bad, msg in (([], "no confirmatory seeds"), ([9101, 9101], "more than once"), (["x1"], "not an integer"),
                     ([-3], "negative")):
        with pytest.raises(ValueError, match=msg):
            check_confirm_seeds(bad, PROFILES)


def test_the_cli_refuses_a_used_seed_before_writing_anything(tmp_path, capsys):
    from semmatch.experiments.confirm import add_confirm_parser, add_ship_parser

    rc = pipeline.main(["confirm", "--seeds", "9101", "7001", "--name", "never"], (add_confirm_parser, add_ship_parser))
    assert rc == 1
    assert "seed 7001 is a development evaluation seed (profile full" in capsys.readouterr().err
    assert not (ROOT / "figures" / "confirm" / "never").exists()
    assert not (ROOT / "data" / "confirm" / "never").exists()


def test_confirm_parameters_replace_only_the_evaluation_seeds(tmp_path):
    out = confirm.write_confirm_params([9101, 9102], tmp_path / "params.yaml", base_profile="full")
    got = pipeline.load_params(out, "full")
    base = pipeline.load_params(ROOT / "params.yaml", "full")
    assert got["common"]["eval_seeds"] == [9101, 9102]
    got["common"]["eval_seeds"] = base["common"]["eval_seeds"]
    assert {k: v for k, v in got.items()} == {k: v for k, v in base.items()}
    assert confirm.confirm_name([9101, 9102]) == "seeds-9101-9102"
    assert confirm.confirm_name(range(9101, 9125)) == "seeds-9101-9124-n24"


def test_a_profile_without_shipped_networks_needs_allow_training(tmp_path):
    with pytest.raises(ValueError, match=r"uses the shipped networks.*no shipped checkpoint.*--allow-training"):
        confirm.run_confirm([9101], base_profile="smoke", out_root=tmp_path, name="t")
    assert not (tmp_path / "figures").exists()


def test_notebook_02_declares_the_train_switch_and_the_shipped_folder(monkeypatch):
    import papermill as pm

    # a parameter papermill cannot parse is silently not declared, and --train would never reach it
    declared = pm.inspect_notebook(str(ROOT / "notebooks" / "02_train_segmentation.ipynb"))
    assert {"retrain", "shipped_models"} <= set(declared)
    assert pipeline.notebook_parameters("02_train_segmentation", "full")["shipped_models"] == "models/full"
    seen = {}
    monkeypatch.setattr(pipeline, "run_notebook", lambda nb, profile, **kw: seen.update(kw))
    monkeypatch.setenv(pipeline.TRAIN_ENV, "1")  # make repro TRAIN=1
    assert pipeline.main(["run", "02_train_segmentation", "--quiet"]) == 0
    assert seen["retrain"] is True
    monkeypatch.delenv(pipeline.TRAIN_ENV)
    seen.clear()
    assert pipeline.main(["run", "02_train_segmentation", "--quiet"]) == 0
    assert "retrain" not in seen


@pytest.mark.notebooks
@pytest.mark.slow
def test_a_smoke_sized_confirm_run_writes_every_table(tmp_path):
    """One fresh seed through every evaluation study of the smoke profile."""
    # the smoke profile with 2 training steps per network: the run trains them (smoke ships none)
    data = yaml.safe_load((ROOT / "params.yaml").read_text())
    data["profiles"]["smoke"]["train_segmentation"]["steps"] = {"compact": 2, "strong": 2}
    params = tmp_path / "params.yaml"
    params.write_text(yaml.safe_dump(data))
    rec = confirm.run_confirm([9101], base_profile="smoke", allow_training=True, out_root=tmp_path, name="smoke",
                              params_file=params)
    figures = tmp_path / "figures" / "confirm" / "smoke"
    reports = tmp_path / "reports" / "confirm" / "smoke"
    data = tmp_path / "data" / "confirm" / "smoke"
    assert json.loads((figures / "confirm.json").read_text()) == rec
    assert rec["seeds"] == [9101] and rec["networks_from"] == "trained here"
    # smoke ships no adaptation: notebook 09 is skipped (a confirmatory run fine-tunes nothing)
    assert rec["skipped"] == confirm.SKIPPED and rec["adapted_networks_from"] == "skipped"
    assert "09_adapt_robot_view" not in rec["wall_seconds"]
    assert (figures / "verdicts.md").is_file()
    assert sorted(p.stem for p in reports.glob("*.ipynb")) == [n for n in pipeline.NOTEBOOKS if n not in confirm.SKIPPED]
    assert yaml.safe_load((data / "params.yaml").read_text())["profiles"]["smoke"]["common"]["eval_seeds"] == [9101]
    for table in ("table2_per_scene", "table2_synthetic", "table3_per_scene", "table3_real", "fig3_height_per_scene",
                  "claims_synthetic", "claims_real", "claims_height", "table_panoptic_per_scene", "verdicts",
                  "claims_all"):
        assert (figures / f"{table}.csv").is_file(), table
    scenes = set(_scene_column(figures / "table2_per_scene.csv"))
    assert scenes and all(s.endswith("_9101") for s in scenes), scenes


def _scene_column(path):
    import pandas as pd

    return pd.read_csv(path)["scene"].astype(str)


def test_where_a_confirmatory_run_takes_its_adapted_networks(tmp_path):
    """Shipped (notebook 09 then uses them or fails), or skipped."""
    (tmp_path / "full").mkdir()
    assert confirm.adapted_networks_source(tmp_path / "full") is None
    (tmp_path / "full" / "adapted").mkdir()
    (tmp_path / "full" / "adapted" / "adaptation.json").write_text("{}")
    assert confirm.adapted_networks_source(tmp_path / "full") == "shipped"
    assert "09_adapt_robot_view" in confirm.SKIPPED and confirm.ADAPT_NOTEBOOK == "09_adapt_robot_view"


def test_the_in_home_study_runs_in_the_confirm_homes(tmp_path, monkeypatch):
    """``--in-home``: the plan's study in the homes of the run's seeds (its kinds x seeds), after the notebooks."""
    import semmatch.experiments.claims as claims
    import semmatch.experiments.in_home as in_home

    order, seen = [], {}
    monkeypatch.setattr(confirm, "run_notebook", lambda nb, profile, **kw: order.append(nb))
    monkeypatch.setattr(claims, "judge_figures", lambda figures: order.append("verdicts"))

    def fake_study(data, figures, **kw):
        order.append("in_home")
        seen.update(kw, data=Path(data), figures=Path(figures))

    monkeypatch.setattr(in_home, "run_in_home_study", fake_study)
    record = confirm.run_confirm([9911, 9912], name="inhome", out_root=tmp_path, in_home=True)
    plan = in_home.load_in_home_plan()
    assert order[-2:] == ["verdicts", "in_home"] and "01_simulate" in order
    assert seen["homes"] == [(k, s) for s in (9911, 9912) for k in plan.kinds]
    assert seen["data"] == tmp_path / "data" / "confirm" / "inhome" / "in_home"
    assert seen["figures"] == tmp_path / "figures" / "confirm" / "inhome" / "in_home"
    assert record["in_home"] is True and "in_home" in record["wall_seconds"]


def test_the_in_home_study_needs_its_plans_profile(tmp_path):
    with pytest.raises(ValueError, match="in-home plan uses the networks of profile 'full'"):
        confirm.run_confirm([9913], base_profile="smoke", out_root=tmp_path, in_home=True, allow_training=True)
    assert not any(tmp_path.iterdir())  # refused before anything was written


def test_the_in_home_studys_seeds_are_refused(tmp_path):
    from semmatch.experiments.in_home import load_in_home_plan

    seed = load_in_home_plan().seeds[0]
    with pytest.raises(ValueError, match=f"refusing confirmatory seeds \\[{seed}\\].*in-home study"):
        confirm.run_confirm([seed], out_root=tmp_path)
    assert not any(tmp_path.iterdir())
