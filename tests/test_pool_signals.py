"""A parallel ``semmatch transfer --jobs 2`` never hangs: a worker killed mid-run (as by the
out-of-memory killer) ends the run with a clear message within 10 s, and SIGTERM or SIGINT to the
process group ends it within 5 s with exit 143 / 130; in every case no process of the run is left
and nothing half-written is in place.

The runs are separate processes (``start_new_session``: their own process group) on a sequence of
thousands of frames made of hard links to four small simulated ones, long enough to be mid-run
when the test acts.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from semmatch.cli import main

pytestmark = [pytest.mark.slow,  # three runs of a separate process (about 15 s each on a quiet machine)
              pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")]

FRAMES = 20000  # hard links: the run needs minutes, the test acts in its first seconds


@pytest.fixture(scope="module")
def long_sequence(tmp_path_factory) -> Path:
    """``seq`` (FRAMES frames, four distinct ones repeated) and ``scene.ply`` (its labelled scene mesh)."""
    d = tmp_path_factory.mktemp("pool")
    assert main(["simulate", "--scene-kind", "living_room", "--seed", "3", "--frames", "4", "--image-size", "64x48",
                 "--camera-height", "0.3", "--quiet", "--out", str(d / "short"),
                 "--save-scene", str(d / "scene.ply")]) == 0
    short, seq = d / "short", d / "seq"
    seq.mkdir()
    for name in ("intrinsics.json", "meta.json"):
        (seq / name).write_bytes((short / name).read_bytes())
    for sub in ("rgb", "depth"):
        (seq / sub).mkdir()
        for i in range(FRAMES):
            os.link(short / sub / f"{i % 4:06d}.png", seq / sub / f"{i:06d}.png")
    poses = [line.split(maxsplit=1)[1] for line in (short / "poses.txt").read_text().splitlines()
             if line and not line.startswith("#")]
    (seq / "poses.txt").write_text("".join(f"{i}.0 {poses[i % 4]}\n" for i in range(FRAMES)))
    return d


def _start(d: Path, out: str) -> subprocess.Popen:
    env = {**os.environ, "OMP_NUM_THREADS": "1", "SEMMATCH_NO_INDEX_CACHE": "1", "PYTHONFAULTHANDLER": "1"}
    return subprocess.Popen([sys.executable, "-m", "semmatch", "transfer", "seq", "--map", "scene.ply",
                             "--method", "3d-neighborhood", "--jobs", "2", "--quiet", "--out", out],
                            cwd=d, env=env, start_new_session=True, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True, preexec_fn=_sigint_as_in_a_terminal)


def _sigint_as_in_a_terminal() -> None:
    """In the child before it runs semmatch: SIGINT as a command typed in a terminal has it. A
    test run started in the background of a script (``pytest ... &``) ignores SIGINT, and Python
    then keeps it ignored: Ctrl-C would not reach the command at all."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _group(pgid: int) -> list[int]:
    """Live (not zombie) processes of process group ``pgid``."""
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(fields[2]) == pgid and fields[0] != "Z":
                found.append(int(entry.name))
    return found


def _children(pid: int) -> list[int]:
    return [p for p in _group(pid) if p != pid]


def _mid_run(d: Path, out: str, proc: subprocess.Popen) -> None:
    """Wait until both workers run and have written some label images into the temporary folder."""
    deadline = time.monotonic() + 240
    while time.monotonic() < deadline:
        assert proc.poll() is None, proc.stderr.read()
        written = sum(len(os.listdir(t)) for t in d.glob(f".{out}.*.partial"))
        if written >= 20 and len(_children(proc.pid)) >= 2:
            return
        time.sleep(0.05)
    pytest.fail("the run did not get going within 240 s")


def _ends_within(proc: subprocess.Popen, seconds: float) -> tuple[int, str, float]:
    t = time.monotonic()
    try:
        _, err = proc.communicate(timeout=seconds)
    except subprocess.TimeoutExpired:
        os.kill(proc.pid, signal.SIGABRT)  # faulthandler prints where every thread waits
        try:
            _, err = proc.communicate(timeout=30)
        finally:
            os.killpg(proc.pid, signal.SIGKILL)
        pytest.fail(f"the run was still going {seconds:g} s later; its threads:\n{err[-5000:]}")
    return proc.returncode, err, time.monotonic() - t


def _no_trace(d: Path, out: str, pgid: int) -> None:
    deadline = time.monotonic() + 2  # a worker's SIGKILL from the kernel may take a moment
    while _group(pgid) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not _group(pgid), f"processes of the run outlived it: {_group(pgid)}"
    assert not (d / out).exists(), "an output was left in place"
    assert not list(d.glob(f".{out}*")), f"left behind: {[p.name for p in d.glob(f'.{out}*')]}"


def test_a_killed_worker_ends_the_run_with_a_clear_message_within_10_s(long_sequence):
    d, out = long_sequence, "killed_worker"
    proc = _start(d, out)
    _mid_run(d, out, proc)
    os.kill(_children(proc.pid)[0], signal.SIGKILL)
    rc, err, took = _ends_within(proc, 10)
    assert rc == 2 and "Traceback" not in err, err
    assert "a worker process died" in err and "were not transferred" in err, err
    _no_trace(d, out, proc.pid)


@pytest.mark.parametrize("sig,code", [(signal.SIGTERM, 143), (signal.SIGINT, 130)])
def test_a_signal_to_the_group_ends_the_run_within_5_s(long_sequence, sig, code):
    d, out = long_sequence, f"signalled_{sig.name}"
    proc = _start(d, out)
    _mid_run(d, out, proc)
    os.killpg(proc.pid, sig)
    rc, err, took = _ends_within(proc, 5)
    assert rc == code, err
    assert "nothing half-written was left in place" in err and "Traceback" not in err, err
    _no_trace(d, out, proc.pid)
