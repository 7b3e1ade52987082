"""semmatch: 3D semantic label transfer across human and robot viewpoints.

Modules: :mod:`semmatch.labels`, :mod:`semmatch.geometry`, :mod:`semmatch.io`,
:mod:`semmatch.sim`, :mod:`semmatch.segment`, :mod:`semmatch.fusion`, :mod:`semmatch.transfer`,
:mod:`semmatch.metrics`, :mod:`semmatch.experiments`, :mod:`semmatch.cli`.
"""

__version__ = "0.1.0"
