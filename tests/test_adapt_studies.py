"""semmatch.experiments.adapt_studies and scripts/adapt_heldout.py: the held-out adaptation scenes,
the labels' quality per class, the pairing with the stage's adaptation, missing inputs."""

from __future__ import annotations

import argparse
import importlib.util

import numpy as np
import pandas as pd
import pytest

from semmatch.experiments.adapt_studies import (
    HELDOUT_ADAPT_SEEDS,
    HELDOUT_SUFFIX,
    check_heldout_seeds,
    heldout_vs_in_sample,
    label_quality_by_class,
    stage_recipe,
)
from semmatch.experiments.pipeline import ROOT, read_params
from semmatch.experiments.protocol import used_seeds
from semmatch.io.labels import id_of
from semmatch.segment.adapt import RobotViews
from semmatch.segment.data import Views

_spec = importlib.util.spec_from_file_location("adapt_heldout", ROOT / "scripts" / "adapt_heldout.py")
heldout = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(heldout)

_PROFILES = read_params(ROOT / "params.yaml")["profiles"]


def test_heldout_seeds_are_fresh():  # make confirm refuses them: tests/test_confirm.py
    assert len(HELDOUT_ADAPT_SEEDS) == 24 and len(set(HELDOUT_ADAPT_SEEDS)) == 24
    assert not set(HELDOUT_ADAPT_SEEDS) & set(used_seeds(_PROFILES))
    cfg = {"train_seeds": list(range(1, 37)), "val_seeds": [501, 502], "eval_seeds": [7001]}
    check_heldout_seeds(HELDOUT_ADAPT_SEEDS, cfg)  # fresh scenes pass
    with pytest.raises(ValueError, match=r"\[8301\] are training seeds of the network"):
        check_heldout_seeds(HELDOUT_ADAPT_SEEDS, {**cfg, "train_seeds": [8301]})
    with pytest.raises(ValueError, match=r"\[502\] are validation seeds"):
        check_heldout_seeds([502, 8302], cfg)
    with pytest.raises(ValueError, match=r"\[1001\] are used by params.yaml"):
        check_heldout_seeds([1001], cfg)  # the full profile's development seed


def _robot() -> RobotViews:
    wall, floor, chair = id_of("wall"), id_of("floor"), id_of("chair")
    gt = np.array([[[wall, wall, floor, floor], [chair, chair, floor, 0]]], np.uint8)
    depth = np.ones(gt.shape, np.float32)
    depth[0, 0, 0] = 0.0  # no depth: left out
    views = Views(np.zeros((*gt.shape, 3), np.uint8), depth, gt, np.zeros(1, np.int64), np.full(1, 0.2, np.float32))
    labels = np.array([[[chair, wall, floor, wall], [chair, 0, floor, floor]]], np.uint8)
    return RobotViews(views, {"3d-neighborhood": labels}, {"3d-neighborhood": 0.8}, ["x_1"])


def test_label_quality_per_class_counts_pixels_with_depth_and_ground_truth():
    q = label_quality_by_class(_robot(), ["3d-neighborhood"]).set_index("category")
    # valid pixels: wall@(0,1), floor@(0,2),(0,3), chair@(1,0),(1,1), floor@(1,2); (0,0) no depth, (1,3) no gt
    assert sorted(q.index) == ["chair", "floor", "wall"]  # in label order
    assert q.loc["floor", "gt_share"] == pytest.approx(3 / 6)
    assert q.loc["wall", "labelled"] == 2 and q.loc["wall", "precision"] == pytest.approx(0.5)  # (0,1) right, (0,3) wrong
    assert q.loc["wall", "recall"] == pytest.approx(1.0)
    assert q.loc["floor", "precision"] == pytest.approx(1.0) and q.loc["floor", "recall"] == pytest.approx(2 / 3)
    assert q.loc["chair", "precision"] == pytest.approx(1.0) and q.loc["chair", "recall"] == pytest.approx(0.5)


def _per_scene(gain_in: list[float], gain_out: list[float]) -> pd.DataFrame:
    rows = []
    for i, (gi, go) in enumerate(zip(gain_in, gain_out)):
        sc = f"office_{7001 + i}"
        base = {0.2: 0.40, 1.6: 0.60}
        for h in (0.2, 1.6):
            rows.append({"model": "compact", "scene": sc, "height": h, "miou": base[h]})
            rows.append({"model": "compact~3d-neighborhood", "scene": sc, "height": h, "miou": base[h] + (gi if h == 0.2 else 0.0)})
            rows.append({"model": "compact~3d-neighborhood" + HELDOUT_SUFFIX, "scene": sc, "height": h,
                         "miou": base[h] + (go if h == 0.2 else -0.01)})
    return pd.DataFrame(rows)


def test_heldout_vs_in_sample_pairs_scenes():
    t = heldout_vs_in_sample(_per_scene([0.10, 0.12, 0.14, 0.12], [0.08, 0.11, 0.11, 0.10]), "compact",
                             ["3d-neighborhood"]).iloc[0]
    assert t["scenes"] == 4
    assert t["gap_closed_in_sample"] == pytest.approx(0.12 / 0.2)
    assert t["gap_closed_held_out"] == pytest.approx(0.10 / 0.2)
    assert t["gain_low_diff"] == pytest.approx(-0.02) and t["gain_low_diff_lo"] < -0.02 < t["gain_low_diff_hi"] < 0
    assert t["change_high_diff"] == pytest.approx(-0.01)
    with pytest.raises(ValueError, match="no scores of .*self-training"):
        heldout_vs_in_sample(_per_scene([0.1, 0.1], [0.1, 0.1]), "compact", ["self-training"])


def test_stage_recipe_and_the_scripts_missing_inputs(tmp_path):
    with pytest.raises(FileNotFoundError, match="validation_adapt_recipe.csv: run stage 09"):
        stage_recipe(tmp_path)
    pd.DataFrame([{"lr": 0.004, "upper_share": 0.5, "steps": 1600, "batch_size": 16, "distill": 0.0, "seed": 0,
                   "chosen": False}]).to_csv(tmp_path / "validation_adapt_recipe.csv", index=False)
    with pytest.raises(ValueError, match="no row is marked chosen"):
        stage_recipe(tmp_path)
    pd.DataFrame([{"lr": 0.004, "upper_share": 0.5, "steps": 1600, "batch_size": 16, "distill": 0.0, "seed": 0,
                   "chosen": True}]).to_csv(tmp_path / "validation_adapt_recipe.csv", index=False)
    r = stage_recipe(tmp_path, seed=3)
    assert (r.lr, r.steps, r.seed) == (0.004, 1600, 3)
    p = {"figures_dir": str(tmp_path), "data_root": str(tmp_path / "data"), "network": "compact",
         "sources": ["3d-neighborhood"]}
    args = argparse.Namespace(out=tmp_path / "out", figures=tmp_path / "fig")
    with pytest.raises(SystemExit, match="adapt_height_per_scene.csv: run stage 09"):
        heldout.score(args, p)
    pd.DataFrame(columns=["model", "scene", "height", "miou"]).to_csv(tmp_path / "adapt_height_per_scene.csv", index=False)
    with pytest.raises(SystemExit, match=r"compact~3d-neighborhood.pt is missing: run the finetune phase first"):
        heldout.score(args, p)
    assert not (tmp_path / "fig").exists()
