"""Installing semmatch as a library (README "Install as a library"): ``constraints.txt`` holds the
tested pins, and with it pip resolves the CPU build's torch 2.13.0 and no NVIDIA wheel."""

from __future__ import annotations

import json
import subprocess
import venv
from pathlib import Path

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
def test_a_fresh_venv_resolves_cpu_torch_2_13_and_no_nvidia_wheel(tmp_path):
    venv.create(tmp_path / "venv", with_pip=True)
    python = str(tmp_path / "venv" / "bin" / "python")
    probe = subprocess.run([python, "-m", "pip", "install", "--dry-run", "--no-deps", "--quiet", "torch==2.13.0"],
                           capture_output=True, text=True, timeout=600)
    if probe.returncode != 0:
        pytest.skip(f"pip reaches no index with torch 2.13.0: {probe.stderr.strip()[-300:]}")
    report = tmp_path / "report.json"
    run = subprocess.run([python, "-m", "pip", "install", "--dry-run", "--quiet", "--report", str(report),
                          "-c", str(ROOT / "constraints.txt"), str(ROOT)],
                         capture_output=True, text=True, timeout=1200)
    assert run.returncode == 0, run.stderr[-2000:]
    chosen = {canonicalize_name(item["metadata"]["name"]): item["metadata"]["version"]
              for item in json.loads(report.read_text())["install"]}
    assert chosen["torch"].split("+")[0] == "2.13.0", chosen["torch"]
    assert not [n for n in chosen if n.startswith("nvidia-") or n == "triton"], sorted(chosen)
    assert "semmatch" in chosen
