"""semmatch on a real Dask cluster: a ``dask scheduler`` and two ``dask worker`` processes started on
127.0.0.1 as subprocesses (no client of this process is involved, none is left behind).

The tasks run on those workers and give the local run's results (also ``semmatch simulate
--dataset --scheduler``, byte for byte); a worker killed mid-run leaves the run to the other one;
a run whose workers all vanish fails after its stated timeout; a failed run stops its tasks that
are still running before the error is reported, so that none of them writes afterwards.
"""

from __future__ import annotations

import hashlib
import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from semmatch.runtime import engine

pytestmark = pytest.mark.slow

WORKERS = ("w0", "w1")


def _no_default_client() -> bool:
    from distributed import default_client

    try:
        default_client()
    except ValueError:
        return True
    return False


def _kill(proc: subprocess.Popen) -> None:
    """Kill a `dask` process and its children (a worker's nanny and worker) and reap it."""
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
    proc.wait(timeout=30)


@pytest.fixture(scope="module")
def _processes(tmp_path_factory):
    """A scheduler on a free port of 127.0.0.1 (its workers: :func:`cluster`); every process is
    killed at the end of the module, whatever the tests did."""
    sched_file = tmp_path_factory.mktemp("dask") / "scheduler.json"
    # the scheduler and the workers import this module (its task functions) as pytest does
    path = os.pathsep.join(p for p in (str(Path(__file__).parent), os.environ.get("PYTHONPATH")) if p)
    # a task is given up after its second worker died under it (Dask's default: the fourth)
    env = {**os.environ, "PYTHONUNBUFFERED": "1", "PYTHONPATH": path,
           "DASK_DISTRIBUTED__SCHEDULER__ALLOWED_FAILURES": "1"}
    env.pop(engine.SCHEDULER_ENV, None)
    popen = dict(env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    procs: dict[str, subprocess.Popen] = {}
    try:
        procs["scheduler"] = subprocess.Popen(
            [sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1", "--port", "0",
             "--no-dashboard", "--scheduler-file", str(sched_file)], **popen)
        deadline, address = time.monotonic() + 60, None
        while address is None and time.monotonic() < deadline:
            try:  # Dask writes the file in place: it may exist before its content does
                address = json.loads(sched_file.read_text())["address"]
            except (FileNotFoundError, ValueError, KeyError):
                time.sleep(0.1)
        assert address and address.startswith("tcp://127.0.0.1:"), f"no scheduler address in {sched_file} after 60 s"
        yield {"address": address, "procs": procs, "popen": popen}
    finally:
        for proc in procs.values():
            _kill(proc)


@pytest.fixture
def cluster(_processes):
    """The scheduler with two single-threaded `dask worker` processes (with nannies), started
    again where a test killed them; no Dask client of this process before or after the test."""
    assert _no_default_client(), "a Dask client lingers in this process: the test would not be alone"
    procs, address = _processes["procs"], _processes["address"]
    for name in WORKERS:
        if name not in procs or procs[name].poll() is not None:
            procs[name] = subprocess.Popen(
                [sys.executable, "-m", "distributed.cli.dask_worker", address, "--name", name, "--nthreads", "1",
                 "--host", "127.0.0.1", "--no-dashboard", "--death-timeout", "60"], **_processes["popen"])
    from distributed import Client

    with Client(address, timeout="30s", set_as_default=False) as c:
        c.wait_for_workers(len(WORKERS), timeout=90)
    yield _processes
    assert _no_default_client(), "a Dask client was left behind"


def _square_where(x: int) -> tuple[int, str | None, str | None]:
    """x squared, the worker it ran on (None: not on a worker) and its OMP_NUM_THREADS."""
    time.sleep(0.2)  # long enough for both workers to get tasks
    try:
        from distributed import get_worker

        name = get_worker().name
    except ValueError:
        name = None
    return x * x, name, os.environ.get("OMP_NUM_THREADS")


def _write(args: tuple[str, int, float]) -> int:
    """Sleep, then write ``<folder>/<i>.txt`` atomically (temporary file, rename); task 99 fails."""
    folder, i, seconds = args
    if i == 99:
        raise RuntimeError("task 99 fails on purpose")
    time.sleep(seconds)
    path = Path(folder) / f"{i}.txt"
    tmp = path.with_suffix(".partial")
    tmp.write_text(str(i * i))
    os.replace(tmp, path)
    return i * i


def _crash_on_3(i: int) -> int:
    """Task 3 ends its worker process, as the out-of-memory killer would; the others return i."""
    if i == 3:
        os._exit(1)
    return i


def _digests(root: Path) -> dict[str, str]:
    return {p.relative_to(root).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}


def test_tasks_run_on_the_cluster_s_workers_and_equal_the_local_run(cluster, tmp_path):
    from semmatch.cli import main

    local = engine.map_tasks(_square_where, range(6), progress=False)
    remote = engine.map_tasks(_square_where, range(6), scheduler=cluster["address"], progress=False)
    assert [r[0] for r in remote] == [r[0] for r in local] == [x * x for x in range(6)]
    assert {r[1] for r in local} == {None} and {r[1] for r in remote} == set(WORKERS)  # both workers ran tasks
    assert {r[2] for r in remote} == {"1"}  # the workers' threads were set (semmatch.runtime.threads)

    tiny = ["--train-seeds", "--eval-seeds", "9001", "--kinds", "living_room", "bedroom", "--frames", "3",
            "--sweep", "--size", "48x36", "--quiet"]
    assert main(["simulate", "--dataset", str(tmp_path / "serial"), *tiny]) == 0  # in this process
    assert main(["simulate", "--dataset", str(tmp_path / "cluster"), "--scheduler", cluster["address"], *tiny]) == 0
    serial = _digests(tmp_path / "serial")
    assert len(serial) > 10 and _digests(tmp_path / "cluster") == serial


def _when_files(folder: Path, n: int, action, limit: float = 60) -> threading.Thread:
    """Run ``action`` in a thread as soon as ``folder`` holds ``n`` result files."""
    def watch():
        deadline = time.monotonic() + limit
        while len(list(folder.glob("*.txt"))) < n and time.monotonic() < deadline:
            time.sleep(0.01)
        action()

    th = threading.Thread(target=watch, daemon=True)
    th.start()
    return th


def test_a_killed_worker_leaves_the_run_to_the_other_one(cluster, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    watcher = _when_files(out, 1, lambda: _kill(cluster["procs"]["w1"]))  # a node lost mid-run
    results = engine.map_tasks(_write, [(str(out), i, 0.3) for i in range(8)], scheduler=cluster["address"],
                               progress=False)
    watcher.join(timeout=30)
    assert cluster["procs"]["w1"].poll() is not None  # it was killed while the run went on
    assert results == [i * i for i in range(8)]
    assert sorted(p.name for p in out.iterdir()) == sorted(f"{i}.txt" for i in range(8))  # nothing half-written
    assert all((out / f"{i}.txt").read_text() == str(i * i) for i in range(8))


def test_a_failed_run_stops_its_running_tasks_before_the_error_is_reported(cluster, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    items = [(str(out), 99, 0.0), *[(str(out), i, 3.0) for i in range(1, 4)]]  # 99 fails while 1 sleeps
    with pytest.raises(RuntimeError, match="task 99 fails on purpose"):
        engine.map_tasks(_write, items, scheduler=cluster["address"], progress=False)
    time.sleep(4.0)  # longer than a running task would need to write
    assert not list(out.iterdir()), "a task of the failed run wrote after the error"


def test_a_task_that_kills_its_workers_is_a_clear_error_naming_it(cluster):
    # Dask gives up the task whose workers died too often: the crashing one, or (when the scheduler
    # had queued it on the same worker) one beside it; the message says so and names the task
    with pytest.raises(engine.ClusterError, match=r"task \d \(\d\) was on workers that died under it"):
        engine.map_tasks(_crash_on_3, range(5), scheduler=cluster["address"], progress=False)


def test_a_run_whose_workers_all_vanish_fails_after_its_timeout(cluster, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    watcher = _when_files(out, 1, lambda: [_kill(cluster["procs"][w]) for w in WORKERS])
    t = time.monotonic()
    # the no-worker timeout, or, on a loaded machine where the scheduler saw the tasks' workers die
    # one by one before the last went, its KilledWorker verdict: either way a clear error, no hang
    with pytest.raises(engine.ClusterError, match=r"has had no worker for 2 s; \d+ of 12 tasks unfinished"
                                                  r"|was on workers that died under it"):
        engine.map_tasks(_write, [(str(out), i, 0.5) for i in range(12)], scheduler=cluster["address"],
                         progress=False, timeout=2)
    assert time.monotonic() - t < 30  # not a hang
    watcher.join(timeout=30)
    assert not list(out.glob("*.partial"))
