"""Where work runs: task engine, process pools, thread limits, progress display.

The pipeline's stages compute; this package only decides how and where that work runs:
:mod:`~semmatch.runtime.engine` (a list of independent tasks in this process, on a local Dask
cluster or on one elsewhere), :mod:`~semmatch.runtime.workers` (process pools whose workers die
with their parent), :mod:`~semmatch.runtime.threads` (how many threads the numerical libraries
use, set once) and :mod:`~semmatch.runtime.progress` (progress bars for Jupyter, a shell or an
executed report). A stage's results do not depend on where it ran.

Nothing is imported here: :mod:`~semmatch.runtime.threads` must run before numpy and torch load
(the CLI imports it first), and the files of the data contract (:mod:`semmatch.io`) use the
progress bars without loading Dask.
"""
