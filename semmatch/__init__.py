"""semmatch: 3D semantic label transfer across human and robot viewpoints.

Packages, in the pipeline's order: :mod:`semmatch.io` (files of the data contract, public
recordings, and the vocabulary everything shares: :mod:`semmatch.io.labels`,
:mod:`semmatch.io.geometry`), :mod:`semmatch.sim` (simulated scenes), :mod:`semmatch.segment`
(segmentation networks and their adaptation to the robot's view), :mod:`semmatch.poses`
(odometry, registration, trajectory errors), :mod:`semmatch.fusion` (semantic TSDF),
:mod:`semmatch.transfer` (label and instance transfer and their kernels),
:mod:`semmatch.online` (the robot online: frame by frame), :mod:`semmatch.evaluate`
(measures, reference, statistics), :mod:`semmatch.experiments` (the pipeline's stages),
:mod:`semmatch.plots` (figures and interactive 3D views) and :mod:`semmatch.cli`; beneath them
all :mod:`semmatch.runtime` (where work runs: task engine, process pools, thread limits,
progress). Nothing else lives at the top (``tests/test_layout.py`` holds it to twelve entries).

The flat module paths of earlier versions (``metrics``, ``odometry``, ``geometry``, ``engine``,
... directly under ``semmatch``) and the old function names (``prepare``, ``fuse``) are gone:
import from the packages above.
"""

import os as _os

__version__ = "0.1.0"

# Open3D switches itself to its WebRTC visualiser (and prints a banner into every executed
# report) when imported in a Jupyter kernel; semmatch views maps with plotly (semmatch.show), so
# the switch is off unless the user asks for it (OPEN3D_DISABLE_WEB_VISUALIZER=false).
_os.environ.setdefault("OPEN3D_DISABLE_WEB_VISUALIZER", "true")

