"""The README's "A person and a robot" commands run as written: a simulated person and robot, the
person's map, ``align`` (accepted), ``transfer --align``, the robot's map, ``show``; then the same robot
as a ROS 2 bag and as a TUM RGB-D folder, each through ``align`` and ``transfer --align``.

The block's lines up to the first ``# the same robot as ...`` comment run once (a module fixture);
each ``# the same robot as ...`` group is its own test."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
LAYOUT_GROUP = "# the same robot as"


def readme_groups(section: str = "## A person and a robot") -> list[list[str]]:
    """The command lines of the first ``bash`` block under ``section`` of the README, in groups: the
    main chain, then one group per ``# the same robot as ...`` comment (other comments dropped)."""
    text = (ROOT / "README.md").read_text()
    start = text.index(section)
    block = re.search(r"```bash\n(.*?)```", text[start:], re.S)
    assert block, f"README: no bash block under {section!r}"
    groups: list[list[str]] = [[]]
    for ln in block.group(1).splitlines():
        ln = ln.strip()
        if ln.startswith(LAYOUT_GROUP):
            groups.append([])
        cmd = ln.split("  #")[0].strip()
        if cmd and not cmd.startswith("#"):
            groups[-1].append(cmd)
    return groups


def readme_commands() -> list[str]:
    """Every command line of the block, in order."""
    return [c for g in readme_groups() for c in g]


def run_lines(cmds: list[str], cwd: Path) -> None:
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}",
           "SEMMATCH_CACHE_DIR": str(cwd / "cache")}
    for cmd in cmds:
        cmd = cmd.replace("python scripts/", f"{sys.executable} {ROOT / 'scripts'}/")
        run = subprocess.run(cmd, shell=True, cwd=cwd, env=env, capture_output=True, text=True, timeout=900)
        assert run.returncode == 0, f"{cmd}\n{run.stderr[-3000:]}"


def test_the_readme_block_is_found():
    main, *layouts = readme_groups()
    assert main[0].startswith("semmatch simulate") and any(c.startswith("semmatch align") for c in main)
    assert any("--align" in c and c.startswith("semmatch transfer") for c in main)
    text = [" ".join(g) for g in layouts]
    assert any("robot_bag" in t for t in text) and any("robot_tum" in t for t in text)
    for g in layouts:  # every other layout goes through align and transfer --align
        assert any(c.startswith("semmatch align") for c in g) and any("--align" in c for c in g)


@pytest.fixture(scope="module")
def pair_dir(tmp_path_factory):
    """The main chain of the block, run once."""
    cwd = tmp_path_factory.mktemp("readme_pair")
    run_lines(readme_groups()[0], cwd)
    return cwd


@pytest.mark.slow
def test_the_readme_real_pair_runs_as_written(pair_dir):
    pair = pair_dir / "pair2"
    assert json.loads((pair / "robot_in_person.txt.json").read_text())["accepted"] is True
    assert len(list((pair / "robot_labels").glob("*.png"))) == 40
    assert (pair / "robot.ply").stat().st_size > 0 and (pair / "robot.html").stat().st_size > 0


@pytest.mark.slow
@pytest.mark.parametrize("layout", ["bag", "tum"])
def test_the_same_robot_in_another_layout(pair_dir, layout):
    group = next(g for g in readme_groups()[1:] if f"robot_{layout}" in " ".join(g))
    run_lines(group, pair_dir)
    pair = pair_dir / "pair2"
    assert json.loads((pair / f"{layout}_in_person.txt.json").read_text())["accepted"] is True
    assert len(list((pair / f"{layout}_labels").glob("*.png"))) == 40
