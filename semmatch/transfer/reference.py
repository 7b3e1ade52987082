"""The published ``3d-neighborhood``: a closest-point query on the semantic mesh per pixel.

The authors' code back-projects every pixel and calls Open3D's
``RaycastingScene.compute_closest_points`` on the mesh, then reads the label of the hit
triangle. This is kept as the reference backend and the benchmark baseline.
"""

from __future__ import annotations

import numpy as np

from .frames import FrameData
from .index import MapIndex

__all__ = ["reference_neighborhood"]


def reference_neighborhood(fd: FrameData, index: MapIndex) -> np.ndarray:
    """Per-pixel exact nearest-surface label (mesh: Open3D closest point; points: KD-tree).

    Parameters
    ----------
    fd : FrameData
    index : MapIndex
        Only its ``RaycastingScene`` / KD-tree and ``max_distance`` are used (no grid).

    Returns
    -------
    uint8 (H,W)
        0 where the depth is missing or the nearest surface is farther than ``max_distance``.
    """
    pts, pix = fd.points()
    out = np.zeros(fd.shape, np.uint8)
    if len(pts):
        lab, _ = index.nearest(pts, index.max_distance)
        out.reshape(-1)[pix] = lab
    return out
