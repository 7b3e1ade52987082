"""Deprecated alias of :mod:`semmatch.poses.trajectory_metrics` (moved there; this path goes in the next release)."""

from semmatch import _moved_module

_moved_module(__name__, "semmatch.poses.trajectory_metrics")
