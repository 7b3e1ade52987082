"""Worker processes die with their parent, even when it is killed with SIGKILL."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest

from semmatch.runtime.workers import process_pool

_CHILD = """
import os, sys, time
from semmatch.runtime.workers import process_pool

def work(i):
    with open(os.path.join(sys.argv[1], f"{{i}}.pid"), "w") as fh:
        fh.write(str(os.getpid()))
    time.sleep(60)

if __name__ == "__main__":
    with process_pool(2, spawn={spawn}) as pool:
        list(pool.map(work, range(2)))
"""


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    with open(f"/proc/{pid}/stat") as fh:  # a zombie waits for its reaper: it is gone
        return fh.read().split(")")[-1].split()[0] != "Z"


def _square(x: int) -> int:
    return x * x


def test_pool_computes():
    with process_pool(2) as pool:
        assert list(pool.map(_square, range(5))) == [0, 1, 4, 9, 16]


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="PR_SET_PDEATHSIG is Linux-only")
@pytest.mark.parametrize("spawn", [False, True])
def test_workers_die_when_the_parent_is_killed(tmp_path, spawn):
    script = tmp_path / "child.py"
    script.write_text(_CHILD.format(spawn=spawn))
    pid_dir = tmp_path / "pids"
    pid_dir.mkdir()
    proc = subprocess.Popen([sys.executable, str(script), str(pid_dir)])
    deadline = time.monotonic() + 60
    while len(list(pid_dir.glob("*.pid"))) < 2 and time.monotonic() < deadline:
        time.sleep(0.05)
    time.sleep(0.1)  # the files are written before the workers sleep
    pids = [int(p.read_text()) for p in sorted(pid_dir.glob("*.pid"))]
    assert len(pids) == 2
    assert all(_alive(p) for p in pids)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    deadline = time.monotonic() + 10
    while any(_alive(p) for p in pids) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not any(_alive(p) for p in pids), "workers outlived their killed parent"


def _omp_threads(_: int) -> str | None:
    return os.environ.get("OMP_NUM_THREADS")


def test_pool_workers_run_on_one_thread(monkeypatch):
    from semmatch.runtime.threads import ENV_VARS, THREADS_ENV

    for name in (THREADS_ENV, *ENV_VARS):
        monkeypatch.delenv(name, raising=False)
    with process_pool(2, spawn=True) as pool:
        assert set(pool.map(_omp_threads, range(2))) == {"1"}
    monkeypatch.setenv(THREADS_ENV, "2")
    with process_pool(1, spawn=True) as pool:
        assert list(pool.map(_omp_threads, range(1))) == ["2"]


_OPENCV_THEN_FORK = """
import cv2
import numpy as np
from semmatch.runtime.workers import process_pool

def work(x):
    return float(cv2.GaussianBlur(np.full((64, 64), x, np.float32), (5, 5), 1).mean())

if __name__ == "__main__":
    cv2.setNumThreads(2)
    img = np.random.default_rng(0).random((1500, 1500)).astype(np.float32)
    for _ in range(3):
        cv2.GaussianBlur(img, (31, 31), 5)  # OpenCV's thread pool now runs in this process
    with process_pool(2) as pool:
        print(list(pool.map(work, [1.0, 2.0])), flush=True)
    print(cv2.getNumThreads())
"""


def test_a_forked_pool_after_opencv_threads_does_not_hang(tmp_path):
    """Forked workers used to hang in ``cv2.setNumThreads`` on the OpenCV pool they inherited
    (a ``transfer_sequence(jobs=2)`` after one with ``jobs=1`` in the same process)."""
    script = tmp_path / "child.py"
    script.write_text(_OPENCV_THEN_FORK)
    try:
        out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=120)
    except subprocess.TimeoutExpired:
        pytest.fail("the forked pool hung after OpenCV had run its thread pool in the parent")
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.split() == ["[1.0,", "2.0]", "2"]  # the parent's OpenCV setting is back after the pool


def _worker_signals(_: int) -> tuple[bool, bool]:
    return signal.getsignal(signal.SIGTERM) == signal.SIG_DFL, signal.getsignal(signal.SIGINT) == signal.SIG_IGN


def test_workers_die_on_sigterm_and_ignore_sigint_whatever_the_parent_set():
    """A forked worker would inherit the command's SIGTERM handler (which raises instead of
    dying) and survive the SIGTERM its pool ends it with."""
    from semmatch.io.outputs import terminate_as_interrupt

    with terminate_as_interrupt(), process_pool(2) as pool:
        assert set(pool.ordered(_worker_signals, range(4))) == {(True, True)}


def test_ordered_yields_in_order():
    with process_pool(2) as pool:
        assert list(pool.ordered(_square, range(30), ahead=2)) == [x * x for x in range(30)]


def test_an_exception_in_the_block_ends_the_workers_at_once():
    t = time.monotonic()
    with pytest.raises(RuntimeError, match="stop"):
        with process_pool(2) as pool:
            running = [pool.submit(time.sleep, 60) for _ in range(6)]
            while not any(f.running() for f in running):
                time.sleep(0.01)
            raise RuntimeError("stop")
    assert time.monotonic() - t < 20, "the pool waited for its tasks instead of ending its workers"
    assert all(f.done() for f in running)
