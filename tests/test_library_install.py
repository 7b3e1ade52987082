"""Installing semmatch as a library (README "Install as a library"): ``constraints.txt`` holds the
tested pins, and with it pip resolves the CPU build's torch 2.13.0 and no NVIDIA wheel in a fresh
venv (the resolution runs in the background from the start of the session: tests/library_install.py)."""

from __future__ import annotations

import json
from pathlib import Path

import library_install
import pytest
from packaging.utils import canonicalize_name

ROOT = Path(__file__).resolve().parents[1]


def _pins(name: str) -> dict[str, str]:
    out = {}
    for line in (ROOT / name).read_text().splitlines():
        line = line.split("#")[0].strip()
        if line:
            pkg, _, ver = line.partition("==")
            assert ver, f"{name}: {line!r} is not pinned with =="
            out[canonicalize_name(pkg)] = ver
    return out


def test_constraints_are_the_requirements_pins_and_cpu_torch():
    constraints = _pins("constraints.txt")
    assert constraints.pop("torch") == "2.13.0"
    assert constraints == _pins("requirements.txt")
    assert "-c constraints.txt" in (ROOT / "README.md").read_text()


@pytest.mark.slow
def test_a_fresh_venv_resolves_cpu_torch_2_13_and_no_nvidia_wheel():
    # started when the session collected this test (tests/conftest.py), so it resolved while others ran
    if library_install.STARTED is None:  # run on its own (-k, -p no:...): started now, stopped at the session's end
        library_install.STARTED = library_install.DryRun(ROOT)
    outcome = library_install.STARTED.result()
    if "skip" in outcome:
        pytest.skip(outcome["skip"])
    assert outcome["returncode"] == 0, outcome["stderr"]
    chosen = {canonicalize_name(item["metadata"]["name"]): item["metadata"]["version"]
              for item in json.loads(Path(outcome["report"]).read_text())["install"]}
    assert chosen["torch"].split("+")[0] == "2.13.0", chosen["torch"]
    assert not [n for n in chosen if n.startswith("nvidia-") or n == "triton"], sorted(chosen)
    assert "semmatch" in chosen
    # and for real: semmatch itself installed from the clone (a wheel, not editable) into that fresh
    # venv, seeing the tested pins (this environment's packages, CPU torch among them), runs
    assert outcome["version_rc"] == 0, outcome["version_out"]
    assert outcome["version_out"].startswith("semmatch "), outcome["version_out"]
    assert outcome["semmatch_from"].startswith(outcome["venv"]), outcome["semmatch_from"]
    assert outcome["torch_cuda"] is None  # the CPU build
