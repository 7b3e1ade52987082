"""Process pools whose workers die with the process that started them, and never hang it.

A ``ProcessPoolExecutor`` worker outlives a parent killed with SIGKILL (nothing runs in the
parent to stop it): it keeps its CPU and memory forever. Every pool of semmatch is made by
:func:`process_pool`, whose workers ask the kernel (Linux ``prctl(PR_SET_PDEATHSIG)``) for
SIGKILL when their parent dies, and exit at once when the parent is already gone. Each worker
runs on the workers' thread limit (:func:`semmatch.runtime.threads.configure`, ``"worker"``).

A pool must also end promptly when one of its workers dies, or when the command is stopped:

* workers do not keep the parent's signal handlers (a forked worker inherits the command's
  SIGTERM handler, :func:`semmatch.io.outputs.terminate_as_interrupt`, and would survive the
  SIGTERM with which the pool ends its workers): in a worker SIGTERM kills, and SIGINT (Ctrl-C
  reaches the whole process group) is ignored, as the parent ends its workers itself. SIGINT and
  SIGTERM are blocked while a worker starts, so none arrives before its handlers are reset;
* :meth:`Pool.ordered` keeps only a few tasks queued per worker and returns each result as it
  comes (results should be small: a worker writes large outputs to files itself);
* a worker that dies (the out-of-memory killer, a ``kill -9``) fails the run at once with
  ``BrokenProcessPool``, and leaving the pool's ``with`` block on an exception (Ctrl-C, SIGTERM,
  an error) cancels the queued tasks and ends the workers within seconds (:meth:`Pool.stop`)
  instead of waiting for them.
"""

from __future__ import annotations

import ctypes
import os
import signal
import sys
import time
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures import TimeoutError as FuturesTimeout
from typing import Any

__all__ = ["die_with_parent", "process_pool", "Pool"]

_PR_SET_PDEATHSIG = 1
#: signals blocked while a worker starts, then reset to what a worker does with them
_STOP_SIGNALS = frozenset({signal.SIGINT, signal.SIGTERM})
#: seconds :meth:`Pool.stop` waits for a worker to end after SIGTERM before it sends SIGKILL
STOP_TIMEOUT = 2.0


def die_with_parent(parent_pid: int | None = None) -> bool:
    """Have the kernel kill this process when its parent dies (Linux; a no-op elsewhere).

    Parameters
    ----------
    parent_pid : int, optional
        The expected parent; when the process has already been re-parented (the parent died
        before this call), it exits immediately.

    Returns
    -------
    bool
        True when the death signal was armed.
    """
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        armed = libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False
    if parent_pid is not None and os.getppid() != parent_pid:
        os._exit(1)
    return armed


def reset_worker_signals() -> None:
    """In a worker process: SIGTERM kills (the default), SIGINT is ignored; then unblock both.

    The parent ends its workers with SIGTERM (and SIGKILL after :data:`STOP_TIMEOUT`); a handler
    inherited from the parent would keep a worker alive and its pool waiting for it.
    """
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, _STOP_SIGNALS)


def _start(parent_pid: int, initializer: Callable | None, initargs: tuple) -> None:
    from .threads import configure

    reset_worker_signals()
    die_with_parent(parent_pid)
    configure("worker")  # one thread per worker process (semmatch.runtime.threads), as Dask workers
    if initializer is not None:
        initializer(*initargs)


def process_pool(
    jobs: int,
    *,
    initializer: Callable | None = None,
    initargs: tuple = (),
    spawn: bool = False,
) -> Pool:
    """A :class:`Pool` (a ``ProcessPoolExecutor``) of ``jobs`` workers that die with this process.

    Parameters
    ----------
    jobs : int
        Number of worker processes.
    initializer, initargs
        As ``ProcessPoolExecutor``: run in every worker after the death signal is armed.
    spawn : bool
        Start workers with ``spawn`` (fresh interpreters: safe with Open3D's and BLAS's thread
        pools) instead of the platform default (``fork`` on Linux: workers share the parent's
        memory, e.g. decoded frames).

    Returns
    -------
    Pool
        Use it as a context manager: leaving the block on an exception stops the workers at once.
    """
    import multiprocessing as mp

    ctx = mp.get_context("spawn") if spawn else None
    forks = not spawn and mp.get_start_method(allow_none=False) == "fork"
    return Pool(max_workers=int(jobs), mp_context=ctx, initializer=_start,
                 initargs=(os.getpid(), initializer, tuple(initargs)), quiet_opencv=forks)


class Pool(ProcessPoolExecutor):
    """A pool that ends its workers at once on an exception, and, when its workers are forked,
    stops OpenCV's thread pool in this process first.

    A forked worker inherits OpenCV's pool without its threads, and the worker's own thread limit
    (``cv2.setNumThreads``) then waits forever for them to stop (seen: a ``transfer_sequence`` with
    ``jobs=2`` after one with ``jobs=1`` in the same process hung). So OpenCV runs on one thread in
    this process while the pool lives, and gets its previous setting back at shutdown.
    """

    def __init__(self, *args, quiet_opencv: bool = False, **kwargs) -> None:
        self._opencv_threads: int | None = None
        if quiet_opencv and "cv2" in sys.modules:
            cv2 = sys.modules["cv2"]
            self._opencv_threads = cv2.getNumThreads()
            if self._opencv_threads != 1:
                cv2.setNumThreads(1)
        super().__init__(*args, **kwargs)

    def _spawn_process(self) -> None:
        # the worker starts with SIGINT and SIGTERM blocked; reset_worker_signals unblocks them
        # once its handlers are its own (a signal that came in between is then acted on)
        previous = signal.pthread_sigmask(signal.SIG_BLOCK, _STOP_SIGNALS)
        try:
            super()._spawn_process()
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, previous)

    def ordered(self, fn: Callable[[Any], Any], items: Iterable[Any], *, ahead: int = 4) -> Iterator[Any]:
        """``fn(item)`` for each item, run in the workers, yielded in the order of ``items``.

        At most ``ahead`` tasks per worker are submitted at any time, so that stopping the pool
        has little to cancel and results come back one by one as they are made.

        Parameters
        ----------
        fn : callable
            A module-level function (pickled to the workers); its results should be small.
        items : iterable
        ahead : int
            Tasks queued per worker.

        Yields
        ------
        object
            Each result.

        Raises
        ------
        concurrent.futures.process.BrokenProcessPool
            A worker died (raised as soon as the pool notices, within a fraction of a second).
        Exception
            The first failing task's own exception.
        """
        window = max(1, int(ahead) * self._max_workers)
        pending: deque = deque()
        it = iter(items)
        for item in it:
            pending.append(self.submit(fn, item))
            if len(pending) >= window:
                break
        while pending:
            fut = pending.popleft()
            while True:  # wake up now and then: signal handlers run in this thread
                try:
                    value = fut.result(timeout=0.5)
                    break
                except FuturesTimeout:
                    continue
            for item in it:
                pending.append(self.submit(fn, item))
                break
            yield value

    def stop(self) -> None:
        """Cancel the queued tasks and end the workers now (SIGTERM, SIGKILL after
        :data:`STOP_TIMEOUT` s); return when they are gone."""
        processes = list((self._processes or {}).values())
        manager = self._executor_manager_thread
        self.shutdown(wait=False, cancel_futures=True)
        for p in processes:
            if p.is_alive():
                p.terminate()
        deadline = time.monotonic() + STOP_TIMEOUT
        for p in processes:
            p.join(max(0.0, deadline - time.monotonic()))
            if p.is_alive():
                p.kill()
                p.join(STOP_TIMEOUT)
        if manager is not None:
            manager.join(STOP_TIMEOUT)
        self._restore_opencv()

    def __exit__(self, exc_type, exc, tb) -> bool:
        if exc_type is None:
            self.shutdown(wait=True)
        else:
            self.stop()
        return False

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        try:
            super().shutdown(wait=wait, cancel_futures=cancel_futures)
        finally:
            if wait:
                self._restore_opencv()

    def _restore_opencv(self) -> None:
        previous, self._opencv_threads = self._opencv_threads, None
        if previous is not None and previous != 1 and "cv2" in sys.modules:
            sys.modules["cv2"].setNumThreads(previous)
