"""The training-seed study: spread over seeds, verdict agreement, CLI errors."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from semmatch.experiments import training_seeds as ts

SCENES = ["apartment_1", "bedroom_1", "office_1"]


def _run(folder, shift: float, verdict: str = "holds"):
    folder.mkdir(parents=True, exist_ok=True)
    rows = []
    for k, scene in enumerate(SCENES):
        for route in ("own", "shared"):
            for ref in ("fusion", "mesh"):
                for model, method, base in (("compact", "lower", 0.8), ("compact", "3d-slic", 0.85),
                                            ("ground truth", "3d-slic", 0.9)):
                    val = base + 0.01 * k + (shift if model != "ground truth" else 0.0)
                    if route == "shared" or ref == "mesh":
                        val = 0.0  # not a headline row: must not reach the spread
                    rows.append(dict(scene=scene, route=route, reference=ref, model=model, method=method,
                                     mean_acc=val))
    pd.DataFrame(rows).to_csv(folder / "table2_per_scene.csv", index=False)
    pd.DataFrame([dict(claim="C1", statement="s", data="synthetic", role="primary", verdict=verdict,
                       verdict_mesh="holds", counts="1 holds", paper_in_ci="0 of 1")]).to_csv(
        folder / "verdicts_synthetic.csv", index=False)
    return folder


def test_spread_over_seeds_uses_headline_rows_and_scene_interval(tmp_path):
    runs = {"0": _run(tmp_path / "a", 0.0), "1": _run(tmp_path / "b", 0.02), "2": _run(tmp_path / "c", 0.04)}
    data = ts.read_seed_runs(runs)
    spread = ts.seed_spread(data["table2"], ("model", "method"))
    row = spread[(spread["model"] == "compact") & (spread["method"] == "lower")].iloc[0]
    assert row["seed 0"] == pytest.approx(0.81) and row["seed 2"] == pytest.approx(0.85)
    assert row["mean"] == pytest.approx(0.83) and row["sd"] == pytest.approx(0.02)
    assert row["range"] == pytest.approx(0.04) and row["seeds"] == 3
    # t interval over the shipped run's three scenes (0.80, 0.81, 0.82)
    from scipy import stats
    assert row["scene_ci_half"] == pytest.approx(stats.t.ppf(0.975, 2) * 0.01 / np.sqrt(3))
    gt = spread[spread["model"] == "ground truth"].iloc[0]
    assert gt["sd"] == pytest.approx(0.0)


def test_verdicts_agree_or_not_and_files_written(tmp_path):
    runs = {"0": _run(tmp_path / "a", 0.0), "1": _run(tmp_path / "b", 0.0, verdict="inconclusive")}
    agree = ts.verdict_agreement(ts.read_seed_runs(runs)["verdicts"])
    assert agree.loc[0, "seed 0"] == "holds" and agree.loc[0, "seed 1"] == "inconclusive"
    assert not agree.loc[0, "agree"] and agree.loc[0, "agree_mesh"]
    # a run without the claim's table cannot agree
    (tmp_path / "c").mkdir()
    pd.DataFrame([dict(claim="C2", statement="s", data="real-like", role="primary", verdict="holds",
                       verdict_mesh="holds", counts="", paper_in_ci="")]).to_csv(tmp_path / "c" / "verdicts_real.csv",
                                                                                  index=False)
    runs2 = {"0": runs["0"], "2": tmp_path / "c"}
    agree2 = ts.verdict_agreement(ts.read_seed_runs(runs2)["verdicts"]).set_index("claim")
    assert agree2.at["C1", "seed 2"] == "missing" and not agree2.at["C1", "agree"]
    assert agree2.at["C2", "seed 0"] == "missing" and not agree2.at["C2", "agree_mesh"]
    out = tmp_path / "out"
    assert ts.main(["--run", f"0={runs['0']}", "--run", f"1={runs['1']}", "--out", str(out)]) == 0
    for name in ("training_seeds_table2.csv", "training_seeds_table2.md", "training_seeds_verdicts.csv",
                 "training_seeds.png"):
        assert (out / name).is_file(), name


def test_cli_errors_name_the_problem(tmp_path, capsys):
    with pytest.raises(SystemExit) as e:
        ts.main(["--run", "0", "--out", str(tmp_path)])
    assert e.value.code == 2 and "SEED=FIGURES_DIR" in capsys.readouterr().err
    with pytest.raises(SystemExit) as e:
        ts.main(["--run", f"0={tmp_path / 'nowhere'}", "--out", str(tmp_path / "o")])
    assert e.value.code == 1 and "nowhere: no such figures folder (training seed 0)" in capsys.readouterr().err
    (tmp_path / "empty").mkdir()
    with pytest.raises(SystemExit) as e:
        ts.main(["--run", f"0={tmp_path / 'empty'}", "--out", str(tmp_path / "o")])
    assert e.value.code == 1 and "none of table2_per_scene.csv" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_the_run_script_checks_its_inputs_before_writing(tmp_path):
    import subprocess
    from pathlib import Path

    script = Path(__file__).parents[1] / "scripts" / "training_seeds.sh"
    usage = subprocess.run(["bash", str(script)], capture_output=True, text=True)
    assert usage.returncode == 2 and "DATA CHECKPOINTS OUT SEED" in usage.stderr
    (tmp_path / "ck").mkdir()
    (tmp_path / "ck" / "compact_s1.pt").write_bytes(b"x")
    r = subprocess.run(["bash", str(script), str(tmp_path / "data"), str(tmp_path / "ck"), str(tmp_path / "out"), "1"],
                       capture_output=True, text=True)
    assert r.returncode == 1 and "strong_s1.pt: no such checkpoint" in r.stderr
    (tmp_path / "ck" / "strong_s1.pt").write_bytes(b"x")
    r = subprocess.run(["bash", str(script), str(tmp_path / "data"), str(tmp_path / "ck"), str(tmp_path / "out"), "1"],
                       capture_output=True, text=True)
    assert r.returncode == 1 and "no scenes/ or models/recipe.json" in r.stderr
    assert not (tmp_path / "out").exists()
