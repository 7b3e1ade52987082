"""scripts/adapt_equal_tuning.py: the candidates, the stage's own candidate, missing inputs."""

from __future__ import annotations

import argparse
import importlib.util
from pathlib import Path

import pandas as pd
import pytest

_spec = importlib.util.spec_from_file_location(
    "adapt_equal_tuning", Path(__file__).parents[1] / "scripts" / "adapt_equal_tuning.py")
equal = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(equal)


def _stage_table(folder: Path, lr: float, share: float) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    pd.DataFrame([{"candidate": 0, "batch_size": 16, "distill": 0.0, "lr": "0.001", "seed": 0, "steps": 1600,
                   "upper_share": 0.5, "chosen": False},
                  {"candidate": 1, "batch_size": 16, "distill": 0.0, "lr": f"{lr:g}", "seed": 0, "steps": 1600,
                   "upper_share": share, "chosen": True}]).to_csv(folder / "validation_adapt_recipe.csv", index=False)


def test_candidates_are_the_large_grid_on_the_stage_recipe(tmp_path):
    _stage_table(tmp_path / "fig", 0.004, 0.5)
    p = {"figures_dir": str(tmp_path / "fig"), "data_root": str(tmp_path / "data"), "network": "compact"}
    cands, same = equal.trials(p)
    assert [(c["lr"], c["upper_share"]) for c in cands] == [(0.004, 0.5), (0.004, 0.75), (0.0003, 0.5), (0.0003, 0.75)]
    assert all(c["steps"] == 1600 and c["batch_size"] == 16 and c["seed"] == 0 for c in cands)
    assert same == 0  # the stage's own recipe: its checkpoint is the candidate
    args = argparse.Namespace(out=tmp_path / "out")
    assert equal._checkpoint(args, p, "self-training", 0, same) == tmp_path / "data" / "adapted" / "compact~self-training.pt"
    assert equal._checkpoint(args, p, "self-training", 2, same) == tmp_path / "out" / "self-training" / "candidate2.pt"
    _stage_table(tmp_path / "fig2", 0.001, 0.5)  # a stage recipe outside the grid: every candidate is fine-tuned
    assert equal.trials({**p, "figures_dir": str(tmp_path / "fig2")})[1] == -1


def test_missing_stage_table_or_checkpoints_are_clear_errors(tmp_path):
    p = {"figures_dir": str(tmp_path / "none"), "data_root": str(tmp_path / "data"), "network": "compact"}
    with pytest.raises(SystemExit, match="validation_adapt_recipe.csv: run stage 09"):
        equal.trials(p)
    _stage_table(tmp_path / "fig", 0.004, 0.5)
    p = {**p, "figures_dir": str(tmp_path / "fig"), "max_forgetting": 0.02, "jobs": 1, "sweep_frame_step": 2}
    args = argparse.Namespace(out=tmp_path / "out", sources=["self-training"], figures=tmp_path / "o")
    with pytest.raises(SystemExit, match="run the finetune phase first: missing .*candidate1.pt"):
        equal.score(args, p)
    assert not (tmp_path / "o").exists()
