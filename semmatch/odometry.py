"""Deprecated alias of :mod:`semmatch.poses.odometry` (moved there; this path goes in the next release)."""

from semmatch import _moved_module

_moved_module(__name__, "semmatch.poses.odometry")
