"""semmatch: 3D semantic label transfer across human and robot viewpoints.

Packages, in the pipeline's order: :mod:`semmatch.io` (files of the data contract, public
recordings), :mod:`semmatch.sim` (simulated scenes), :mod:`semmatch.segment` (segmentation
networks), :mod:`semmatch.poses` (odometry, registration, trajectory errors),
:mod:`semmatch.fusion` (semantic TSDF), :mod:`semmatch.transfer` (label transfer and its
kernels), :mod:`semmatch.evaluate` (measures, reference, statistics),
:mod:`semmatch.experiments` (the pipeline's stages), :mod:`semmatch.plots` and
:mod:`semmatch.cli`; beside them the shared modules :mod:`semmatch.labels`,
:mod:`semmatch.geometry`, :mod:`semmatch.engine` and a few more.

Modules that moved into these packages keep their old import path for one release: a thin
module there makes the old name an alias of the new module and emits a
:class:`DeprecationWarning` naming the new path (:func:`_moved_module`). Renamed functions keep
their old name as well, for one release (:func:`_renamed_function`).
"""

import os as _os

__version__ = "0.1.0"

# Open3D switches itself to its WebRTC visualiser (and prints a banner into every executed
# report) when imported in a Jupyter kernel; semmatch views maps with plotly (semmatch.show), so
# the switch is off unless the user asks for it (OPEN3D_DISABLE_WEB_VISUALIZER=false).
_os.environ.setdefault("OPEN3D_DISABLE_WEB_VISUALIZER", "true")


def _moved_module(old: str, new: str) -> None:
    """Make the module ``old`` an alias of the module ``new``, with a deprecation warning.

    Called by the body of a deprecated module (a *shim*, ``_moved_module(__name__, "new.path")``
    and nothing else): the new module is imported and put in ``sys.modules`` under the old name,
    so ``import old`` and ``from old import x`` give the new module's objects (private names
    included, and the same module object for monkeypatching).

    Parameters
    ----------
    old : str
        The old module name (the shim's ``__name__``).
    new : str
        The module's new name.

    Warns
    -----
    DeprecationWarning
        ``"<old> has moved to <new>"``, attributed to the code that imported ``old``; once per
        process (the alias is then found in ``sys.modules``).
    """
    import importlib
    import sys
    import warnings

    module = importlib.import_module(new)
    warnings.warn(f"{old} has moved to {new}: import it from there ({old} will be removed in the next release)",
                  DeprecationWarning, stacklevel=3)
    sys.modules[old] = module


def _renamed_function(new, old: str, new_name: str):
    """A deprecated alias of the function ``new`` under its old name, kept for one release.

    Parameters
    ----------
    new : callable
        The function under its new name.
    old : str
        The old public name (``"semmatch.fusion.fuse"``).
    new_name : str
        The new public name (``"semmatch.fusion.fuse_sequence"``).

    Returns
    -------
    callable
        Calls ``new`` with the same arguments and returns its result, after a
        :class:`DeprecationWarning` that names ``new_name``, attributed to the caller.
    """
    import functools
    import warnings

    @functools.wraps(new)
    def alias(*args, **kwargs):
        warnings.warn(f"{old} is deprecated: call {new_name} (the same function under a name that says what it "
                      f"computes; {old} will be removed in the next release)", DeprecationWarning, stacklevel=2)
        return new(*args, **kwargs)

    alias.__name__ = alias.__qualname__ = old.rpartition(".")[2]
    alias.__doc__ = f"Deprecated name of :func:`{new_name}` (same arguments, same result); goes in the next release."
    return alias
