"""Semantic TSDF fusion: posed RGB-D frames and their labels into a labelled mesh or point cloud.

:mod:`~semmatch.fusion.tsdf` holds the volume (:class:`SemanticTSDF`: Open3D's voxel-block TSDF
with one log-evidence channel per category, a Bayesian label update per surface point);
:mod:`~semmatch.fusion.reconstruction` the drivers that fuse a whole sequence with it
(:func:`fuse_sequence`, :func:`extract`, :func:`reconstruct`, :func:`reconstruct_many`). Every public
name is importable from ``semmatch.fusion`` itself; :func:`check_depth_units` (from
:mod:`semmatch.io`) and :func:`default_device` (from :mod:`semmatch.runtime.engine`) are re-exported
here as before.
"""

from ..io import DEPTH_UNIT_RANGE, check_depth_units  # noqa: F401 (DEPTH_UNIT_RANGE: as before)
from ..runtime.engine import default_device
from .reconstruction import extract, fuse_sequence, reconstruct, reconstruct_many
from .tsdf import EvidencePixels, SemanticTSDF

__all__ = ["SemanticTSDF", "EvidencePixels", "fuse_sequence", "extract", "reconstruct", "reconstruct_many",
           "check_depth_units", "default_device"]
