"""The README's "A person and a robot" commands run as written: a simulated person and robot, the
person's map, ``align`` (accepted), ``transfer --align``, the robot's map, ``show``, and the same robot
as a ROS 2 bag through ``align`` and ``transfer --align``."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def readme_commands(section: str = "## A person and a robot") -> list[str]:
    """The command lines of the first ``bash`` block under ``section`` of the README (comments dropped)."""
    text = (ROOT / "README.md").read_text()
    start = text.index(section)
    block = re.search(r"```bash\n(.*?)```", text[start:], re.S)
    assert block, f"README: no bash block under {section!r}"
    lines = [ln.split("  #")[0].strip() for ln in block.group(1).splitlines()]
    return [ln for ln in lines if ln and not ln.startswith("#")]


def test_the_readme_block_is_found():
    cmds = readme_commands()
    assert cmds[0].startswith("semmatch simulate") and any(c.startswith("semmatch align") for c in cmds)
    assert any("--align" in c and c.startswith("semmatch transfer") for c in cmds)
    assert any("robot_bag" in c and c.startswith("semmatch align") for c in cmds)


@pytest.mark.slow
def test_the_readme_real_pair_runs_as_written(tmp_path):
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}",
           "SEMMATCH_CACHE_DIR": str(tmp_path / "cache")}
    for cmd in readme_commands():
        cmd = cmd.replace("python scripts/", f"{sys.executable} {ROOT / 'scripts'}/")
        run = subprocess.run(cmd, shell=True, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=900)
        assert run.returncode == 0, f"{cmd}\n{run.stderr[-3000:]}"
    pair = tmp_path / "pair2"
    for report in ("robot_in_person.txt.json", "bag_in_person.txt.json"):
        assert json.loads((pair / report).read_text())["accepted"] is True, report
    assert len(list((pair / "robot_labels").glob("*.png"))) == 40 == len(list((pair / "bag_labels").glob("*.png")))
    assert (pair / "robot.ply").stat().st_size > 0 and (pair / "robot.html").stat().st_size > 0
