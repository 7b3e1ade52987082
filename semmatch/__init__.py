"""semmatch: 3D semantic label transfer across human and robot viewpoints.

Modules: :mod:`semmatch.labels`, :mod:`semmatch.geometry`, :mod:`semmatch.io`,
:mod:`semmatch.sim`, :mod:`semmatch.segment`, :mod:`semmatch.fusion`, :mod:`semmatch.transfer`,
:mod:`semmatch.metrics`, :mod:`semmatch.experiments`, :mod:`semmatch.cli`.
"""

import os as _os

__version__ = "0.1.0"

# Open3D switches itself to its WebRTC visualiser (and prints a banner into every executed
# report) when imported in a Jupyter kernel; semmatch views maps with plotly (semmatch.show), so
# the switch is off unless the user asks for it (OPEN3D_DISABLE_WEB_VISUALIZER=false).
_os.environ.setdefault("OPEN3D_DISABLE_WEB_VISUALIZER", "true")
