"""`dvc exp show`, `dvc params diff` and `dvc metrics show` stay readable: the parameters of the
profiles that are not active stay out (they live in profiles.yaml, of which each stage tracks only
its keys of the active profile; DVC shows all of params.yaml), and every stage's headline numbers
are one metrics file (one row, not one row per stage and a dash per other stage's number)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from semmatch.experiments.pipeline import OVERRIDABLE, PROFILES_FILE, read_params

ROOT = Path(__file__).resolve().parents[1]
DVC = Path(sys.executable).with_name("dvc")


def test_stages_track_params_yaml_top_level_and_the_active_profiles_keys_only():
    top = yaml.safe_load((ROOT / "params.yaml").read_text())
    assert set(top) == {"profile", *OVERRIDABLE}  # no profiles: DVC would show every profile's keys
    stages = yaml.safe_load((ROOT / "dvc.yaml").read_text())["stages"]
    for name, st in stages.items():
        tracked = [p for p in st["params"] if isinstance(p, str)]
        assert set(tracked) <= set(top), name
        [of_profiles] = [p for p in st["params"] if isinstance(p, dict)]
        assert list(of_profiles) == [PROFILES_FILE], name
        assert all(k.startswith("profiles.${profile}.") for k in of_profiles[PROFILES_FILE]), name
    assert set(read_params(ROOT / "params.yaml")["profiles"]) >= {"full", "smoke"}


def _dvc(*args: str) -> dict:
    run = subprocess.run([str(DVC), *args], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr[-2000:]
    return json.loads(run.stdout)


@pytest.mark.slow
@pytest.mark.skipif(not DVC.is_file(), reason="dvc not installed in this environment")
@pytest.mark.skipif(not (ROOT / ".git").exists(), reason="not a git checkout (dvc needs one)")
def test_dvc_shows_the_active_profiles_params_and_one_row_of_metrics():
    active = yaml.safe_load((ROOT / "params.yaml").read_text())["profile"]
    shown = _dvc("params", "diff", "--all", "--json")  # the workspace's values ("new") of every tracked file
    keys = [k for f in shown.values() for k, v in f.items() if v.get("new") is not None]
    assert keys and all(k.split(".")[1] == active for k in keys if k.startswith("profiles.")), \
        sorted({k.split(".")[1] for k in keys if k.startswith("profiles.")})
    metrics = _dvc("metrics", "show", "--json")[""]["data"]
    assert list(metrics) == [f"figures/{active}/metrics.json"]
