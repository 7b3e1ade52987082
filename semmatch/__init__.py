"""semmatch: 3D semantic label transfer across human and robot viewpoints.

Packages, in the pipeline's order: :mod:`semmatch.io` (files of the data contract, public
recordings), :mod:`semmatch.sim` (simulated scenes), :mod:`semmatch.segment` (segmentation
networks), :mod:`semmatch.poses` (odometry, registration, trajectory errors),
:mod:`semmatch.fusion` (semantic TSDF), :mod:`semmatch.transfer` (label transfer and its
kernels), :mod:`semmatch.evaluate` (measures, reference, statistics),
:mod:`semmatch.experiments` (the pipeline's stages), :mod:`semmatch.plots` and
:mod:`semmatch.cli`; beside them the shared modules :mod:`semmatch.labels`,
:mod:`semmatch.geometry`, :mod:`semmatch.engine` and a few more.

The flat module paths of earlier versions (``metrics``, ``odometry``, ... directly under
``semmatch``) and the old function names (``prepare``, ``fuse``) were kept for one release as
deprecated aliases and are gone: import from the packages above.
"""

import os as _os

__version__ = "0.1.0"

# Open3D switches itself to its WebRTC visualiser (and prints a banner into every executed
# report) when imported in a Jupyter kernel; semmatch views maps with plotly (semmatch.show), so
# the switch is off unless the user asks for it (OPEN3D_DISABLE_WEB_VISUALIZER=false).
_os.environ.setdefault("OPEN3D_DISABLE_WEB_VISUALIZER", "true")

