"""Where per-scene work runs: in this process, on a local Dask cluster, or on a cluster elsewhere.

Every per-scene stage of the pipeline (simulating a scene, transferring + fusing a scene's robot
frames, the panoptic study) is a list of independent tasks, each a pure function of its inputs
(own seeds; outputs written atomically, so a task that runs twice writes the same bytes).
:func:`map_tasks` runs such a list:

* ``jobs == 1`` and no scheduler: in this process, one after the other (no cluster; debugging);
* ``jobs > 1``: on a ``dask.distributed.LocalCluster`` of ``jobs`` single-threaded worker
  processes, started once per process and reused (its workers die with this process, also when
  it is killed: :func:`semmatch.runtime.workers.die_with_parent` runs in each of them; each is pinned to
  its own CPU, so that the workers do not compete for the cores: :func:`dask_setup`);
* a scheduler address (``scheduler=`` argument, else ``SEMMATCH_SCHEDULER``, which
  ``python -m semmatch.experiments run --scheduler`` and a profile's ``common.scheduler`` set):
  on that cluster, e.g. one started by dask-jobqueue on SLURM (docs/cluster.md). The workers
  must reach the same files (a shared file system) and have semmatch installed.

Dask reschedules the task of a worker that dies on another worker; results come back in input
order and do not depend on where they ran. A run fails with :class:`ClusterError` (a clear
message, no traceback from the CLI) when a task has killed ``distributed.scheduler.allowed-failures``
+ 1 workers (it names the item), when the scheduler goes away, or when the cluster has had no
worker for ``worker_timeout`` seconds (``SEMMATCH_WORKER_TIMEOUT``, default 300). On any failure,
Ctrl-C included, the run's unfinished tasks are cancelled and the workers still executing one are
ended (their nannies start new ones; a local cluster is closed), so that nothing of the run keeps writing after the error is reported. Every task
runs with the thread limits of :func:`semmatch.runtime.threads.configure` (``"worker"``).

The per-frame pool inside one sequence (``transfer_sequence(..., jobs=N)``) stays a process pool
(:mod:`semmatch.runtime.workers`): its tasks are milliseconds long and share one large map index, which a
pool initialiser hands each worker once.

:func:`default_device` names the Open3D device the GPU-capable kernels (fusion, odometry) use
by default.
"""

from __future__ import annotations

import atexit
import logging
import os
import sys
import time
import warnings
from collections.abc import Callable, Iterable
from typing import Any

__all__ = ["map_tasks", "resolve_scheduler", "check_scheduler", "SCHEDULER_ENV", "WORKER_TIMEOUT_ENV",
           "ClusterError", "close_local_cluster", "pin_to_cpu",
           "default_device"]

#: environment variable naming a Dask scheduler address to run per-scene tasks on
SCHEDULER_ENV = "SEMMATCH_SCHEDULER"
#: seconds to wait for a scheduler before giving up (a live one answers in milliseconds; the
#: rest of the 10 s a refused address may take goes to start-up: imports, parameters)
CONNECT_TIMEOUT = 6
#: environment variable: seconds a run waits while its cluster has no worker before it fails
WORKER_TIMEOUT_ENV = "SEMMATCH_WORKER_TIMEOUT"
#: default of ``SEMMATCH_WORKER_TIMEOUT``: long enough for a SLURM job that replaces an expired one
#: to start when the queue is short; raise it where jobs wait longer
WORKER_TIMEOUT = 300.0
#: seconds to wait for the workers of a failed run's running tasks to end
_RESTART_TIMEOUT = 15


class ClusterError(ValueError):
    """The cluster could not finish a run: a task that killed its workers, a scheduler that went
    away, or no worker for longer than the worker timeout (the message says which, and names the item)."""

_LOCAL: dict = {}  # "client", "cluster", "workers", "pid" of the process's local cluster


def default_device() -> str:
    """``"CUDA:0"`` when Open3D was built with CUDA and a GPU is present, else ``"CPU:0"``."""
    import open3d as o3d

    return "CUDA:0" if o3d.core.cuda.is_available() else "CPU:0"


def resolve_scheduler(scheduler: str | None = None) -> str | None:
    """The scheduler address to use: the argument, else ``SEMMATCH_SCHEDULER``, else None (local)."""
    addr = scheduler if scheduler not in (None, "") else os.environ.get(SCHEDULER_ENV) or None
    return None if addr in (None, "", "local") else str(addr)


def dask_setup(worker) -> None:
    """Run in every local worker process: die with the process that started the cluster, own one core.

    Each worker is pinned to one CPU (:func:`pin_to_cpu`, by its index in the cluster), so the
    workers stop competing for the cores (stages 04, 05 and 07 ran 9-28 % faster pinned, 2026-11-25). Pinning
    is not what makes the real-like chain repeatable: the odometry, the registration and the
    real-like scene tasks limit Open3D to one thread themselves (:mod:`semmatch.poses.rgbd_odometry`).
    """
    from .threads import configure
    from .workers import die_with_parent

    die_with_parent(int(os.environ.get("SEMMATCH_PARENT_PID", "0")) or None)
    configure("worker")
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
                           silence_logs=logging.ERROR, preload=["semmatch.runtime.engine"])
    client = Client(cluster, set_as_default=False)  # no default client left behind for other code
    if dashboard:
        print(f"[semmatch] Dask dashboard: {client.dashboard_link}", file=sys.stderr)  # stdout: results only
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


def worker_timeout(value: float | None = None) -> float:
    """Seconds a run may wait while its cluster has no worker: ``value``, else
    ``SEMMATCH_WORKER_TIMEOUT``, else :data:`WORKER_TIMEOUT`.

    Raises
    ------
    ValueError
        A value that is not a positive number of seconds.
    """
    raw = value if value is not None else os.environ.get(WORKER_TIMEOUT_ENV) or WORKER_TIMEOUT
    try:
        seconds = float(raw)
    except (TypeError, ValueError):
        raise ValueError(f"the worker timeout must be a number of seconds, got {raw!r} ({WORKER_TIMEOUT_ENV})") from None
    if not seconds > 0:
        raise ValueError(f"the worker timeout must be > 0 s, got {raw!r} ({WORKER_TIMEOUT_ENV})")
    return seconds


def _call(fn: Callable[..., Any], item: Any) -> Any:
    """Run one task on a worker, with the workers' thread limits (set once per process)."""
    from .threads import configure

    configure("worker")
    return fn(item)


def _running_keys(keys: list, dask_worker=None) -> list:
    """The ``keys`` that ``dask_worker`` is still executing (run on the workers by :func:`_stop`)."""
    tasks = dask_worker.state.tasks
    return [k for k in keys if k in tasks and tasks[k].state in ("executing", "long-running", "cancelled", "resumed")]


async def _exit_worker() -> None:
    """End the worker process at once (run on a worker by :func:`_stop`; its nanny starts a new one;
    a coroutine, as Dask runs only those without waiting for a reply)."""
    os._exit(70)


def _stop(client, futures: list) -> None:
    """Cancel the unfinished ``futures`` and end the workers still executing one of them.

    A cancelled task that already runs goes on in its worker's thread (Python threads cannot be
    stopped; a graceful restart waits for it) and would write its outputs after the caller
    reported an error. Its worker process is therefore ended at once, as if it had crashed: the
    worker's nanny starts a new one (a worker without a nanny is gone; dask-jobqueue's ``adapt``
    replaces it). Returns when those workers have left the scheduler, or after a few seconds.
    """
    unfinished = [f for f in futures if not f.done()]
    if not unfinished or client.status != "running":
        return
    keys = [f.key for f in unfinished]
    try:
        client.cancel(unfinished, force=True)
        busy = [addr for addr, ks in client.run(_running_keys, keys, on_error="return").items()
                if isinstance(ks, list) and ks]
        if not busy:
            return
        client.run(_exit_worker, workers=busy, wait=False)
        deadline = time.monotonic() + _RESTART_TIMEOUT
        while set(busy) & set(client.nthreads()) and time.monotonic() < deadline:
            time.sleep(0.05)
        left = set(busy) & set(client.nthreads())
    except Exception as e:  # the scheduler may be gone
        left = {f"{type(e).__name__}: {str(e)[:200]}"}
    if left:
        warnings.warn(f"could not stop the run's remaining tasks on the Dask cluster ({', '.join(sorted(left))}); "
                      "tasks already running may still finish and write their outputs", RuntimeWarning, stacklevel=3)


def _end_local_workers(futures: list) -> None:
    """After a failed run on the local cluster: kill its worker processes (children of this
    process) when a task of the run may still be running, and close the cluster (the next run
    starts a new one). Faster than :func:`_stop`, and it works when Ctrl-C reached the workers too."""
    if all(f.done() for f in futures) or _LOCAL.get("pid") != os.getpid():
        return
    import signal

    for nanny in list(getattr(_LOCAL.get("cluster"), "workers", {}).values()):
        pid = getattr(nanny, "pid", None)
        if pid:
            try:
                os.kill(pid, signal.SIGKILL)
            except (ProcessLookupError, PermissionError):
                pass
    close_local_cluster()


def _n_workers(client) -> int:
    """Workers the scheduler knows now (0 when the client has lost its scheduler)."""
    if client.status != "running":
        return 0
    try:
        return len(client.nthreads())
    except (OSError, TimeoutError):
        return 0


def _raise_for(fut, i: int, item: Any, where: str) -> Any:
    """Raise for task ``i`` that did not finish: a clear :class:`ClusterError` for a task that killed
    its workers or was cancelled, the task's own exception otherwise (a note names the item). A
    task that finished after all (its status changed while it was looked at: recomputed after a
    worker died) returns its result."""
    from distributed.client import FutureCancelledError
    from distributed.scheduler import KilledWorker

    try:
        value = fut.result(timeout=5)  # the error is held by this client: no transfer
    except KilledWorker:
        raise ClusterError(f"task {i} ({item!r:.100}) was on workers that died under it (the {where} gave it "
                           "up after distributed.scheduler.allowed-failures retries): a task of this run kills its "
                           "worker (out of memory, or a crash in native code), this one or one beside it on the "
                           "same worker; run with --jobs 1 to find it") from None
    except FutureCancelledError:
        raise ClusterError(f"task {i} ({item!r:.100}) was cancelled on the {where} (the scheduler went away, "
                           "or another client cancelled it)") from None
    except Exception as e:
        e.add_note(f"(in task {i}: {item!r:.100}, on the {where})")
        raise
    if fut.status == "finished":
        return value
    raise ClusterError(f"task {i} ({item!r:.100}) ended as {fut.status!r} on the {where}")


def _gather(client, futures: list, items: list, *, where: str, desc: str, progress: bool, timeout: float) -> list:
    """The futures' results in input order, with a progress bar; :class:`ClusterError` after
    ``timeout`` seconds without a worker or when the scheduler goes away.

    Results are fetched as tasks finish, on the client's own event loop (no default client is
    needed). A result lost with its worker before it was fetched is recomputed by Dask; the wait
    for it counts towards ``timeout`` like any other while the cluster has no worker.
    """
    from distributed import as_completed

    from .progress import tqdm

    index = {f.key: i for i, f in enumerate(futures)}
    results: list = [None] * len(items)
    ac = as_completed(futures, loop=client.loop, with_results=True, raise_errors=False)
    idle_since = last_check = time.monotonic()
    with tqdm(total=len(items), desc=desc, disable=not progress) as bar:
        while not ac.is_empty():
            if ac.has_ready():
                for fut, value in ac.next_batch(block=False):
                    i = index[fut.key]
                    if fut.status in ("lost", "pending"):  # its worker died under it: Dask recomputes it
                        ac.add(fut)
                        continue
                    if fut.status != "finished":
                        value = _raise_for(fut, i, items[i], where)
                    results[i] = value
                    bar.update()
                continue
            now = time.monotonic()
            if now - last_check >= 0.5:
                last_check = now
                if client.status != "running":
                    raise ClusterError(f"lost the {where} with {ac.count()} of {len(items)} tasks unfinished")
                if _n_workers(client):
                    idle_since = now
                elif now - idle_since > timeout:
                    first = min((index[f.key] for f in futures if f.status != "finished"), default=0)
                    raise ClusterError(f"the {where} has had no worker for {timeout:g} s; {ac.count()} of "
                                       f"{len(items)} tasks unfinished (first: task {first}, {items[first]!r:.100}); "
                                       f"start workers, or raise {WORKER_TIMEOUT_ENV}")
            time.sleep(0.02)
    return results


def map_tasks(fn: Callable[..., Any], items: Iterable[Any], *, jobs: int | None = 1, scheduler: str | None = None,
              desc: str = "tasks", progress: bool = True, timeout: float | None = None) -> list:
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
        Show progress (plain text lines under the pipeline, :mod:`semmatch.runtime.progress`).
    timeout : float, optional
        Seconds the run may wait while the cluster has no worker (default
        ``SEMMATCH_WORKER_TIMEOUT``, else 300); a task that runs long is not a timeout.

    Returns
    -------
    list
        The results, in the order of ``items``.

    Raises
    ------
    ValueError
        ``jobs < 1``, a bad timeout, or a scheduler that cannot be reached (before any task runs).
    ClusterError
        No worker for ``timeout`` seconds, a task whose workers kept dying, or a lost scheduler;
        the run's other tasks are stopped first.
    Exception
        The first failing task's exception (the run's other tasks are stopped first).
    """
    from .progress import tqdm

    items = list(items)
    jobs = (os.cpu_count() or 1) if jobs is None else jobs
    if int(jobs) < 1:
        raise ValueError(f"jobs must be >= 1, got {jobs}")
    address = resolve_scheduler(scheduler)
    wait_s = worker_timeout(timeout)
    if not items:
        return []
    if address is None and (int(jobs) == 1 or len(items) == 1):
        return [fn(item) for item in tqdm(items, desc=desc, disable=not progress)]
    from functools import partial

    client = _remote_client(address) if address else _local_client(min(int(jobs), len(items)), int(jobs))
    where = f"Dask scheduler at {address}" if address else "local Dask cluster"
    futures: list = []
    try:
        # pure=False: every call runs (a task's outputs are files, not only its return value)
        futures = client.map(partial(_call, fn), items, pure=False)
        return _gather(client, futures, items, where=where, desc=desc, progress=progress, timeout=wait_s)
    except BaseException:
        if address:
            _stop(client, futures)
        else:
            _end_local_workers(futures)
        raise
    finally:
        if address:
            client.close()
