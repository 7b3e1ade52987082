"""How many CPU threads the numerical libraries use: set once, in one place.

semmatch runs many small array operations per frame (a label scatter, one small matrix product per
ray batch, a per-frame network pass). Left at their defaults, torch, OpenMP, OpenBLAS and Open3D
each start one thread per core for every such operation; on a machine whose cores are busy
(another process, or the other workers of a cluster) those threads wait for each other, and the
work runs several times slower than on one thread (the semantic TSDF 3-4x; a network pass up to
39x with one other process busy; ``semmatch bench fusion --thread-rows``). semmatch therefore
runs every kind of work on a fixed number of threads:

* **CLI verbs**: :func:`configure` (``"cli"``) at the entry point, before any library is loaded;
* **Dask workers**: :func:`configure` (``"worker"``) when a worker starts and before each task
  (:mod:`semmatch.runtime.engine`), so that a worker of any cluster, started by any means, runs alike;
* **library calls**: ``with limit_threads():`` around a call, restoring the previous settings.

The number is ``SEMMATCH_THREADS`` where it is set, else ``OMP_NUM_THREADS`` where the user set
it, else 1. ``SEMMATCH_THREADS=0`` leaves every library at its own default (to measure them).
Network training has its own setting (``threads`` of the training configuration).
"""

from __future__ import annotations

import os
import sys
from collections.abc import Iterator
from contextlib import contextmanager

__all__ = ["THREADS_ENV", "ENV_VARS", "KINDS", "threads_for", "configure", "limit_threads", "current"]

#: environment variable: CPU threads per process for semmatch's work (0: the libraries' defaults)
THREADS_ENV = "SEMMATCH_THREADS"
#: the thread variables of OpenMP, the BLAS builds and numexpr, read when a library loads
ENV_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "BLIS_NUM_THREADS",
            "VECLIB_MAXIMUM_THREADS", "NUMEXPR_NUM_THREADS")
#: kinds of work and their default threads (``SEMMATCH_THREADS`` overrides every kind)
KINDS = {"cli": 1, "worker": 1, "library": 1}

_CONFIGURED: dict = {}  # pid -> (threads, libraries loaded) at the last configure() of this process


def threads_for(kind: str = "cli") -> int:
    """Threads for ``kind`` of work: ``SEMMATCH_THREADS``, else a user's ``OMP_NUM_THREADS``, else
    the kind's default (0 means: leave the libraries at their defaults).

    Raises
    ------
    ValueError
        An unknown kind, or a thread variable that is not a whole number >= 0.
    """
    if kind not in KINDS:
        raise ValueError(f"unknown kind of work {kind!r}; one of {', '.join(KINDS)}")
    for name in (THREADS_ENV, "OMP_NUM_THREADS"):
        raw = os.environ.get(name, "").strip()
        if raw:
            try:
                n = int(raw)
            except ValueError:
                raise ValueError(f"{name}={raw!r} is not a whole number of threads") from None
            if n < 0 or (n == 0 and name != THREADS_ENV):
                raise ValueError(f"{name}={raw!r}: threads must be >= {0 if name == THREADS_ENV else 1}")
            return n
    return KINDS[kind]


def _set_loaded(n: int) -> dict:
    """Limit the libraries already loaded in this process to ``n`` threads; their previous limits."""
    previous: dict = {}
    if "torch" in sys.modules:
        torch = sys.modules["torch"]
        previous["torch"] = torch.get_num_threads()
        torch.set_num_threads(n)
    if "open3d" in sys.modules and hasattr(sys.modules["open3d"], "utility"):
        utility = sys.modules["open3d"].utility
        if hasattr(utility, "set_max_threads"):
            previous["open3d"] = utility.get_max_threads()
            utility.set_max_threads(n)
    if "numba" in sys.modules:
        numba = sys.modules["numba"]
        previous["numba"] = numba.get_num_threads()
        numba.set_num_threads(min(n, numba.config.NUMBA_NUM_THREADS))
    if "cv2" in sys.modules:  # OpenCV keeps its own pool (SLIC, blurs): the variables do not reach it
        cv2 = sys.modules["cv2"]
        previous["cv2"] = cv2.getNumThreads()
        # a forked process may not touch a pool it inherited (semmatch.runtime.workers)
        if previous["cv2"] != n:
            cv2.setNumThreads(n)
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover  (a dependency of scikit-learn; the libraries keep their own)
        return previous
    previous["threadpoolctl"] = threadpool_limits(limits=n)  # OpenMP and BLAS runtimes loaded so far
    return previous


def configure(kind: str = "cli", n: int | None = None) -> int:
    """Set this process's threads for ``kind`` of work.

    Sets the thread variables (:data:`ENV_VARS`) for libraries loaded later and for child
    processes, and limits torch, Open3D, numba, OpenCV and the OpenMP / BLAS runtimes already loaded.
    A later call with the same number only limits the libraries loaded since (torch and the BLAS
    read the variables when they load; Open3D does not, so a Dask task calls this again).

    Parameters
    ----------
    kind : str
        ``"cli"`` (a ``semmatch`` verb), ``"worker"`` (a Dask worker) or ``"library"``.
    n : int, optional
        Threads (default :func:`threads_for`); 0 leaves every library at its default.

    Returns
    -------
    int
        The threads set (0: none set).
    """
    n = threads_for(kind) if n is None else int(n)
    if n < 0:
        raise ValueError(f"threads must be >= 0, got {n}")
    done = _CONFIGURED.get(os.getpid())
    if done is not None and done[0] == n and done[1] == _loaded():
        return n
    if n > 0:
        for name in ENV_VARS:
            os.environ[name] = str(n)
        _set_loaded(n)
    _CONFIGURED[os.getpid()] = (n, _loaded())
    return n


def _loaded() -> frozenset:
    """The thread-pooled libraries loaded in this process."""
    return frozenset(m for m in ("torch", "open3d", "numba", "numpy", "scipy", "sklearn", "cv2") if m in sys.modules)


def current() -> dict:
    """The thread limits in force now: the thread variables, and torch's, Open3D's and the
    OpenMP / BLAS runtimes' limits where those libraries are loaded (for benchmark reports)."""
    out: dict = {name: os.environ.get(name) for name in (THREADS_ENV, *ENV_VARS)}
    if "torch" in sys.modules:
        out["torch"] = sys.modules["torch"].get_num_threads()
    if "open3d" in sys.modules and hasattr(sys.modules["open3d"], "utility"):
        out["open3d"] = sys.modules["open3d"].utility.get_max_threads()
    try:
        from threadpoolctl import threadpool_info

        out["runtimes"] = {f"{i['internal_api']}": i["num_threads"] for i in threadpool_info()}
    except ImportError:  # pragma: no cover
        pass
    return out


@contextmanager
def limit_threads(n: int | None = None) -> Iterator[int]:
    """Run the block with torch, Open3D, numba, OpenCV and the loaded OpenMP / BLAS runtimes on ``n`` threads.

    For library users: ``with limit_threads(): reconstruct(frames, labels, 0.04)`` runs the
    fusion as the ``semmatch`` verbs do. The previous limits are restored on exit.

    Parameters
    ----------
    n : int, optional
        Threads (default :func:`threads_for` of ``"library"``: ``SEMMATCH_THREADS``, else 1).

    Yields
    ------
    int
        The threads in force inside the block (0: the libraries' defaults, nothing changed).
    """
    n = threads_for("library") if n is None else int(n)
    if n < 0:
        raise ValueError(f"threads must be >= 0, got {n}")
    previous = _set_loaded(n) if n > 0 else {}
    try:
        yield n
    finally:
        if "threadpoolctl" in previous:
            previous.pop("threadpoolctl").restore_original_limits()
        if "torch" in previous:
            sys.modules["torch"].set_num_threads(previous["torch"])
        if "open3d" in previous:
            sys.modules["open3d"].utility.set_max_threads(previous["open3d"])
        if "numba" in previous:
            sys.modules["numba"].set_num_threads(previous["numba"])
        if "cv2" in previous:
            sys.modules["cv2"].setNumThreads(previous["cv2"])
