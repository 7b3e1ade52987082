"""Packaging tells the truth: every import declared, the three dependency files agree, `pip check`
is clean, and JupyterLab starts without Dash's rebuild request."""

from __future__ import annotations

import ast
import json
import re
import subprocess
import sys
import tomllib
from importlib.metadata import PackageNotFoundError, packages_distributions, version
from pathlib import Path

import pytest
import yaml
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name

ROOT = Path(__file__).resolve().parents[1]
PROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
#: imports that are optional by design (each guarded, with a message saying how to get it)
OPTIONAL_IMPORTS = {"habitat_sim", "detectron2", "bokeh"}


def _declared() -> dict[str, Requirement]:
    """Canonical name -> requirement of every dependency in pyproject.toml (core and extras)."""
    reqs = [Requirement(r) for r in PROJECT["dependencies"]]
    reqs += [Requirement(r) for extra in PROJECT["optional-dependencies"].values() for r in extra]
    return {canonicalize_name(r.name): r for r in reqs}


def _pins() -> dict[str, str]:
    """Canonical name -> version pinned in requirements.txt."""
    out = {}
    for line in (ROOT / "requirements.txt").read_text().splitlines():
        line = line.split("#")[0].strip()
        if line:
            name, _, ver = line.partition("==")
            assert ver, f"requirements.txt: {line!r} is not pinned with =="
            out[canonicalize_name(name)] = ver
    return out


def _torch_pins() -> dict[str, str]:
    setup = re.search(r'TORCH="torch==([\w.]+)"', (ROOT / "scripts" / "setup.sh").read_text())
    env = yaml.safe_load((ROOT / "environment.yml").read_text())
    pip = next(d["pip"] for d in env["dependencies"] if isinstance(d, dict))
    conda = next(re.match(r"torch==([\d.]+)", p) for p in pip if p.startswith("torch"))
    comment = re.search(r"torch==([\d.]+)", (ROOT / "requirements.txt").read_text().splitlines()[0])
    return {"scripts/setup.sh": setup.group(1), "environment.yml": conda.group(1),
            "requirements.txt (header)": comment.group(1)}


def test_every_third_party_import_is_declared():
    imports = set()
    for f in (ROOT / "semmatch").rglob("*.py"):
        for node in ast.walk(ast.parse(f.read_text(), filename=str(f))):
            if isinstance(node, ast.Import):
                imports |= {a.name.split(".")[0] for a in node.names}
            elif isinstance(node, ast.ImportFrom) and not node.level and node.module:
                imports.add(node.module.split(".")[0])
    third_party = imports - set(sys.stdlib_module_names) - {"semmatch"} - OPTIONAL_IMPORTS
    dists = packages_distributions()
    declared = set(_declared())
    # a module the environment lacks altogether cannot be mapped: that is a missing declaration too
    undeclared = {m: dists.get(m, ["<not installed>"]) for m in third_party
                  if not {canonicalize_name(d) for d in dists.get(m, [])} & declared}
    # allowed: modules of a declared package's declared extra (dask[distributed] -> distributed)
    undeclared.pop("distributed", None)
    # threadpoolctl: used when present (semmatch.runtime.threads falls back without it)
    undeclared.pop("threadpoolctl", None)
    assert not undeclared, f"imported but not declared in pyproject.toml: {undeclared}"


def test_pyproject_requirements_and_environment_agree():
    pins = _pins()
    for name, req in _declared().items():
        if name == "torch":
            continue  # installed first and alone by scripts/setup.sh (CPU build)
        assert name in pins, f"pyproject.toml declares {name}, requirements.txt does not pin it"
        assert req.specifier.contains(pins[name], prereleases=True), \
            f"requirements.txt pins {name}=={pins[name]}, outside pyproject's {req.specifier}"
    torch = _torch_pins()
    assert len(set(torch.values())) == 1, f"torch pins disagree: {torch}"
    assert _declared()["torch"].specifier.contains(torch["scripts/setup.sh"])
    env = yaml.safe_load((ROOT / "environment.yml").read_text())
    python = next(d for d in env["dependencies"] if isinstance(d, str) and d.startswith("python="))
    assert Requirement(f"x{PROJECT['requires-python']}").specifier.contains(python.split("=")[1] + ".0")
    pip = next(d["pip"] for d in env["dependencies"] if isinstance(d, dict))
    assert "-r requirements.txt" in pip and "-e ." in pip
    build = tomllib.loads((ROOT / "pyproject.toml").read_text())["build-system"]["requires"]
    assert any(Requirement(r).name == "setuptools" and not Requirement(r).specifier.contains("76.1.0") for r in build), \
        "setuptools < 77 rejects `license = \"MIT\"` (an SPDX expression)"


def test_installed_versions_match_the_pins():
    wrong = {}
    for name, ver in _pins().items():
        try:
            have = version(name)
        except PackageNotFoundError:
            have = None
        if have != ver:
            wrong[name] = (ver, have)
    assert not wrong, f"requirements.txt pin -> installed: {wrong} (rerun scripts/setup.sh)"


def test_pip_check_is_clean():
    run = subprocess.run([sys.executable, "-m", "pip", "check"], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stdout + run.stderr


def test_jupyterlab_has_no_build_request_from_dash():
    """What JupyterLab's "Build Recommended" dialog asks (jupyterlab.commands.build_check) is
    empty, and Dash's extension is disabled (scripts/setup.sh)."""
    commands = pytest.importorskip("jupyterlab.commands", reason="JupyterLab is not installed")
    assert commands.build_check(app_options=commands.AppOptions()) == []
    page_config = Path(sys.prefix) / "etc" / "jupyter" / "labconfig" / "page_config.json"
    assert page_config.is_file(), f"{page_config} missing: run scripts/setup.sh"
    disabled = json.loads(page_config.read_text()).get("disabledExtensions", {})
    assert disabled.get("@plotly/dash-jupyterlab") is True


def test_notebooks_give_dash_a_silent_comm(monkeypatch):
    """Open3D imports Dash, which opens a `dash` comm in a kernel; no frontend handles it, so the
    notebooks hand Dash a comm that sends nothing (no nbconvert warning) and leave other comms be."""
    comm = pytest.importorskip("comm")
    from semmatch.experiments.pipeline import _quiet_dash_comm

    sent = []

    def kernel_comm(*args, **kwargs):
        sent.append(kwargs.get("target_name"))
        return "a kernel comm"

    monkeypatch.setattr(comm, "create_comm", kernel_comm)
    _quiet_dash_comm()
    _quiet_dash_comm()  # idempotent: wrapped once
    assert isinstance(comm.create_comm(target_name="dash"), comm.DummyComm)
    assert comm.create_comm(target_name="jupyter.widget") == "a kernel comm"
    assert sent == ["jupyter.widget"]
