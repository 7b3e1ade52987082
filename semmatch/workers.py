"""Process pools whose workers die with the process that started them.

A ``ProcessPoolExecutor`` worker outlives a parent killed with SIGKILL (nothing runs in the
parent to stop it): it keeps its CPU and memory forever. Every pool of semmatch is made by
:func:`process_pool`, whose workers ask the kernel (Linux ``prctl(PR_SET_PDEATHSIG)``) for
SIGKILL when their parent dies, and exit at once when the parent is already gone. Each worker
runs on the workers' thread limit (:func:`semmatch.threads.configure`, ``"worker"``).
"""

from __future__ import annotations

import ctypes
import os
import signal
import sys
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor

__all__ = ["die_with_parent", "process_pool"]

_PR_SET_PDEATHSIG = 1


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


def _start(parent_pid: int, initializer: Callable | None, initargs: tuple) -> None:
    from .threads import configure

    die_with_parent(parent_pid)
    configure("worker")  # one thread per worker process (semmatch.threads), as Dask workers
    if initializer is not None:
        initializer(*initargs)


def process_pool(
    jobs: int,
    *,
    initializer: Callable | None = None,
    initargs: tuple = (),
    spawn: bool = False,
) -> ProcessPoolExecutor:
    """A ``ProcessPoolExecutor`` of ``jobs`` workers that die with this process.

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
    """
    import multiprocessing as mp

    ctx = mp.get_context("spawn") if spawn else None
    forks = not spawn and mp.get_start_method(allow_none=False) == "fork"
    return _Pool(max_workers=int(jobs), mp_context=ctx, initializer=_start,
                 initargs=(os.getpid(), initializer, tuple(initargs)), quiet_opencv=forks)


class _Pool(ProcessPoolExecutor):
    """A pool that, when its workers are forked, stops OpenCV's thread pool in this process first.

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

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        try:
            super().shutdown(wait=wait, cancel_futures=cancel_futures)
        finally:
            previous, self._opencv_threads = self._opencv_threads, None
            if previous is not None and previous != 1 and "cv2" in sys.modules:
                sys.modules["cv2"].setNumThreads(previous)
