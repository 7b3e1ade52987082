"""Where per-scene work runs: in this process, on a local Dask cluster, or on a cluster elsewhere.

Every per-scene stage of the pipeline (simulating a scene, transferring + fusing a scene's robot
frames, the panoptic study) is a list of independent tasks, each a pure function of its inputs
(own seeds; outputs written atomically, so a task that runs twice writes the same bytes).
:func:`map_tasks` runs such a list:

* ``jobs == 1`` and no scheduler: in this process, one after the other (no cluster; debugging);
* ``jobs > 1``: on a ``dask.distributed.LocalCluster`` of ``jobs`` single-threaded worker
  processes, started once per process and reused (its workers die with this process, also when
  it is killed: :func:`semmatch.workers.die_with_parent` runs in each of them; each is pinned to
  its own CPU, so that the workers do not compete for the cores: :func:`dask_setup`);
* a scheduler address (``scheduler=`` argument, else ``SEMMATCH_SCHEDULER``, which
  ``python -m semmatch.experiments run --scheduler`` and a profile's ``common.scheduler`` set):
  on that cluster, e.g. one started by dask-jobqueue on SLURM (docs/cluster.md). The workers
  must reach the same files (a shared file system) and have semmatch installed.

Dask reschedules the task of a worker that dies on another worker; results come back in input
order and do not depend on where they ran. The per-frame pool inside one sequence
(``transfer_sequence(..., jobs=N)``) stays a process pool (:mod:`semmatch.workers`): its tasks are
milliseconds long and share one large map index, which a pool initialiser hands each worker once.
"""

from __future__ import annotations

import atexit
import logging
import os
from collections.abc import Callable, Iterable
from typing import Any

__all__ = ["map_tasks", "resolve_scheduler", "check_scheduler", "SCHEDULER_ENV", "close_local_cluster", "pin_to_cpu"]

#: environment variable naming a Dask scheduler address to run per-scene tasks on
SCHEDULER_ENV = "SEMMATCH_SCHEDULER"
#: seconds to wait for a scheduler before giving up (a live one answers in milliseconds; the
#: rest of the 10 s a refused address may take goes to start-up: imports, parameters)
CONNECT_TIMEOUT = 6

_LOCAL: dict = {}  # "client", "cluster", "workers", "pid" of the process's local cluster


def resolve_scheduler(scheduler: str | None = None) -> str | None:
    """The scheduler address to use: the argument, else ``SEMMATCH_SCHEDULER``, else None (local)."""
    addr = scheduler if scheduler not in (None, "") else os.environ.get(SCHEDULER_ENV) or None
    return None if addr in (None, "", "local") else str(addr)


def dask_setup(worker) -> None:
    """Run in every local worker process: die with the process that started the cluster, own one core.

    Each worker is pinned to one CPU (:func:`pin_to_cpu`, by its index in the cluster), so the
    workers stop competing for the cores (stages 04, 05 and 07 ran 9-28 % faster pinned, 2026-11-25). Pinning
    is not what makes the real-like chain repeatable: the odometry, the registration and the
    real-like scene tasks limit Open3D to one thread themselves (:mod:`semmatch.rgbd_odometry`).
    """
    from .workers import die_with_parent

    die_with_parent(int(os.environ.get("SEMMATCH_PARENT_PID", "0")) or None)
    try:
        index = int(worker.name)
    except (TypeError, ValueError):  # a worker not started by _local_client: leave it as it is
        return
    pin_to_cpu(index)


def pin_to_cpu(index: int) -> int | None:
    """Restrict this process to one of the CPUs it may use: the ``index``-th, cyclically.

    Parameters
    ----------
    index : int
        The worker's index in its cluster (0, 1, ...); workers beyond the number of CPUs share.

    Returns
    -------
    int or None
        The CPU now used, or None where the platform cannot pin (no ``os.sched_setaffinity``) or
        the process may use one CPU only.
    """
    if not hasattr(os, "sched_setaffinity"):
        return None
    cpus = sorted(os.sched_getaffinity(0))
    if len(cpus) < 2:
        return None
    cpu = cpus[int(index) % len(cpus)]
    os.sched_setaffinity(0, {cpu})
    return cpu


def _local_client(jobs: int, most: int | None = None):
    """The process's LocalCluster client with ``jobs`` workers (started on first use).

    A running cluster of this process is reused when it has between ``jobs`` and ``most``
    (default ``jobs``) workers: starting one costs seconds (worker processes import semmatch).
    """
    from distributed import Client, LocalCluster

    if _LOCAL.get("pid") == os.getpid() and jobs <= _LOCAL.get("workers", 0) <= (most or jobs):
        return _LOCAL["client"]
    close_local_cluster()
    try:
        import bokeh  # noqa: F401  (the dashboard needs it)

        dashboard = ":0"
    except ImportError:
        dashboard = None
    os.environ["SEMMATCH_PARENT_PID"] = str(os.getpid())  # read by dask_setup in the workers
    cluster = LocalCluster(n_workers=jobs, threads_per_worker=1, processes=True, dashboard_address=dashboard,
                           silence_logs=logging.ERROR, preload=["semmatch.engine"])
    client = Client(cluster)
    if dashboard:
        print(f"[semmatch] Dask dashboard: {client.dashboard_link}")
    _LOCAL.update(client=client, cluster=cluster, workers=jobs, pid=os.getpid())
    return client


def close_local_cluster() -> None:
    """Stop the process's local cluster (also done at exit)."""
    if _LOCAL.get("pid") == os.getpid():
        for key in ("client", "cluster"):
            try:
                _LOCAL[key].close()
            except Exception:  # already gone (interpreter shutdown)
                pass
    _LOCAL.clear()


atexit.register(close_local_cluster)


def _remote_client(address: str):
    """A client of the scheduler at ``address``; a clear error within ``CONNECT_TIMEOUT`` seconds."""
    from distributed import Client

    try:
        return Client(address, timeout=f"{CONNECT_TIMEOUT}s", set_as_default=False)
    except (OSError, TimeoutError, ValueError) as e:
        raise ValueError(f"cannot reach the Dask scheduler at {address!r} within {CONNECT_TIMEOUT} s "
                         f"({type(e).__name__}: {str(e)[:200]}); is it running? (--scheduler / "
                         f"{SCHEDULER_ENV})") from None


def check_scheduler(address: str) -> None:
    """Connect to the Dask scheduler at ``address`` and disconnect.

    Raises
    ------
    ValueError
        The scheduler cannot be reached within ``CONNECT_TIMEOUT`` seconds.
    """
    _remote_client(address).close()


def map_tasks(fn: Callable[..., Any], items: Iterable[Any], *, jobs: int | None = 1, scheduler: str | None = None,
              desc: str = "tasks", progress: bool = True) -> list:
    """``[fn(item) for item in items]``, run serially, on a local cluster or on a scheduler.

    Parameters
    ----------
    fn : callable
        A module-level function (or ``functools.partial`` of one): it is pickled to the workers.
    items : iterable
        One argument per task.
    jobs : int or None
        Local worker processes (1: run in this process; None: one per CPU core), at most one per
        item. Ignored with a scheduler.
    scheduler : str, optional
        Address of a Dask scheduler (``tcp://host:8786``); default ``SEMMATCH_SCHEDULER``.
    desc : str
        Progress bar label.
    progress : bool
        Show progress (plain text lines under the pipeline, :mod:`semmatch.progress`).

    Returns
    -------
    list
        The results, in the order of ``items``.

    Raises
    ------
    ValueError
        ``jobs < 1``, or a scheduler that cannot be reached (before any task runs).
    Exception
        The first failing task's exception.
    """
    from .progress import tqdm

    items = list(items)
    jobs = (os.cpu_count() or 1) if jobs is None else jobs
    if int(jobs) < 1:
        raise ValueError(f"jobs must be >= 1, got {jobs}")
    address = resolve_scheduler(scheduler)
    if not items:
        return []
    if address is None and (int(jobs) == 1 or len(items) == 1):
        return [fn(item) for item in tqdm(items, desc=desc, disable=not progress)]
    from distributed import as_completed

    client = _remote_client(address) if address else _local_client(min(int(jobs), len(items)), int(jobs))
    try:
        # pure=False: every call runs (a task's outputs are files, not only its return value)
        futures = client.map(fn, items, pure=False)
        index = {f.key: i for i, f in enumerate(futures)}
        results: list = [None] * len(items)
        with tqdm(total=len(items), desc=desc, disable=not progress) as bar:
            for fut in as_completed(futures):
                results[index[fut.key]] = fut.result()
                bar.update()
        return results
    finally:
        if address:
            client.close()
