"""SIGKILL at several points of simulate / reconstruct / transfer / predict / train: the output
is either absent or complete (never partial in place), and a re-run equals an uninterrupted run.

Each command first runs uninterrupted (its wall time T is the clock); then it is started again
and its whole process group is killed after 25 %, 50 % and 80 % of T.
"""

from __future__ import annotations

import hashlib
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow

FRACTIONS = (0.25, 0.5, 0.8)


def _semmatch(*argv: str, cwd: Path) -> subprocess.Popen:
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    return subprocess.Popen([sys.executable, "-m", "semmatch", *argv], cwd=cwd, env=env, start_new_session=True,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)


def _run(*argv: str, cwd: Path) -> float:
    t = time.perf_counter()
    p = _semmatch(*argv, cwd=cwd)
    _, err = p.communicate(timeout=600)
    assert p.returncode == 0, f"semmatch {' '.join(argv)} failed: {err[-800:]}"
    return time.perf_counter() - t


def _digest(path: Path) -> dict[str, str]:
    """Content of a file or folder: relative path -> SHA-256 (hidden entries are not output)."""
    if path.is_file():
        return {"": hashlib.sha256(path.read_bytes()).hexdigest()}
    return {p.relative_to(path).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(path.rglob("*")) if p.is_file() and not p.name.startswith(".")}


def _kill_after(argv: list[str], cwd: Path, seconds: float) -> None:
    p = _semmatch(*argv, cwd=cwd)
    try:
        p.wait(timeout=seconds)
    except subprocess.TimeoutExpired:
        os.killpg(p.pid, signal.SIGKILL)
        p.wait(timeout=30)
    p.stderr.close()


@pytest.fixture(scope="module")
def work(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("kill")
    common = ["--kind", "bedroom", "--seed", "5", "--size", "160x120", "--quiet"]
    _run("simulate", *common, "--frames", "24", "--out", "seq", cwd=d)
    _run("simulate", *common, "--frames", "24", "--height", "0.3", "--out", "low", cwd=d)
    _run("reconstruct", "seq", "--out", "map.ply", "--quiet", cwd=d)
    _run("train", "--recipe", "smoke", "--steps", "2", "--out", "model.pt", "--quiet", cwd=d)
    return d


COMMANDS = {
    "simulate": (["simulate", "--kind", "office", "--seed", "9", "--size", "160x120", "--frames", "40", "--quiet",
                  "--overwrite", "--out", "{out}"], "out_seq"),
    "reconstruct": (["reconstruct", "seq", "--quiet", "--out", "{out}"], "out_map.ply"),
    "transfer": (["transfer", "low", "--map", "map.ply", "--method", "3d-slic", "--quiet", "--overwrite",
                  "--out", "{out}"], "out_labels"),
    "predict": (["predict", "seq", "--model", "model.pt", "--quiet", "--overwrite", "--out", "{out}"], "out_pred"),
}


@pytest.mark.parametrize("name", list(COMMANDS))
def test_a_killed_run_leaves_the_old_or_no_output_and_a_rerun_equals_an_uninterrupted_one(work, name):
    argv, out = COMMANDS[name]
    ref = f"ref_{out}"
    duration = _run(*(a.format(out=ref) for a in argv), cwd=work)
    expected = _digest(work / ref)
    assert expected
    cmd = [a.format(out=out) for a in argv]
    for f in FRACTIONS:
        _kill_after(cmd, work, f * duration)
        target = work / out
        if target.exists():  # the kill came after the swap: the output must be complete
            assert _digest(target) == expected, f"{name} killed at {f:.0%} of {duration:.1f} s left a partial output"
    _run(*cmd, cwd=work)
    assert _digest(work / out) == expected, f"{name}: the re-run after kills differs from an uninterrupted run"
    left = sorted(p.name for p in work.glob(f".{out.rsplit('.', 1)[0]}*"))
    assert not left, f"{name}: the re-run left what the killed runs wrote: {left}"


def test_a_killed_training_leaves_no_checkpoint_or_a_loadable_one(work):
    from semmatch.segment import load_model

    argv = ["train", "--recipe", "smoke", "--steps", "2", "--quiet", "--out", "killed.pt"]
    duration = _run(*argv[:-1], "ref.pt", cwd=work)
    for f in FRACTIONS:
        _kill_after(argv, work, f * duration)
        if (work / "killed.pt").exists():
            load_model(work / "killed.pt")
    # a SIGKILL inside the checkpoint's write leaves its temporary file (nothing can clean up after a
    # SIGKILL); the next run sweeps dead writers' leftovers, as for the other commands above
    _run(*argv, cwd=work)
    load_model(work / "killed.pt")
    assert not [p.name for p in work.glob(".killed*")], "the re-run left what the killed runs wrote"
