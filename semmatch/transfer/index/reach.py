"""Whether a point has a map surface within ``max_distance``: the support test of the points that
the label grid leaves open (the voxels of the ``max_distance`` shell).

Three steps, cheapest first, each giving the exact query's answer for the points it settles:

1. **The voxel's centre distance.** Distance to a surface changes no faster than the point
   moves, so the exact distance ``dc`` at the centre ``c`` of the point's voxel settles every
   point ``p`` with ``|dc - max_distance| > |p - c|``. Centre distances are computed once per
   voxel, the first time a point falls in it, and kept (one byte a stored voxel).
2. **The nearest mesh vertex** (meshes only). The surface is at most as far as the nearest
   vertex, and at least that distance minus the mesh's cover radius
   (:func:`vertex_cover_radius`).
3. **The exact query** (:meth:`MapIndex.nearest <semmatch.transfer.index.MapIndex.nearest>`)
   for the rest.

On fused reconstructions, whose many small triangles put thousands of a frame's points near
``max_distance``, about a tenth of the shell's points reach step 2 (docs/speed.md, "Map
density").
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from .label_grid import BLOCK, BSHIFT

__all__ = ["ReachTest", "vertex_cover_radius", "UNKNOWN"]

#: code of a voxel whose centre distance is not computed yet
UNKNOWN = -128
#: a point counts as settled only with this margin (metres) over the rounding of the stored
#: distance: far above the float32 error of the exact query
_MARGIN = 1e-5


class ReachTest:
    """The support test of an index's shell points, with its memo.

    Parameters
    ----------
    index : MapIndex
        The index whose grid, map and exact queries it uses (its grid must not change after).

    Attributes
    ----------
    codes : int8 (stored voxels,)
        Centre distance of each stored voxel of the grid: ``round((dc - max_distance) / step)``
        with ``step = voxel_size / 128``, clipped to +-127 (beyond that every point of the
        voxel is settled); :data:`UNKNOWN` while not computed.
    """

    def __init__(self, index) -> None:
        self.index = index
        self.codes = np.full(index._blocks.size, UNKNOWN, np.int8)
        self._vertices: tuple | None = None  # KD-tree of the mesh's vertices, cover radius

    @property
    def nbytes(self) -> int:
        """Bytes of the memo."""
        return self.codes.nbytes

    def within(self, points: np.ndarray) -> np.ndarray:
        """Whether each point has a map surface within ``max_distance`` (bool (N,)), exactly as
        the exact query answers it."""
        p = np.ascontiguousarray(points, dtype=np.float32).reshape(-1, 3)
        if len(p) == 0:
            return np.zeros(0, bool)
        index = self.index
        near, unsure = self.centre_bounds(p)
        if index.is_mesh and len(unsure):
            near[unsure], unsure = self.vertex_bounds(p, unsure)
        if len(unsure):
            near[unsure] = np.isfinite(index.nearest(p[unsure], index.max_distance)[1])
        return near

    def centre_bounds(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Settle float32 points (N,3) from their voxel's centre distance (computed on first use).

        Returns
        -------
        near : bool (N,)
            True where a surface is surely within reach (False elsewhere so far).
        unsure : int (M,)
            Indices of the points not settled.
        """
        ix = self.index
        v = ix.voxel_size
        q = (p.astype(np.float64) - ix.origin) / v
        ijk = np.clip(np.floor(q), 0, np.asarray(ix.shape) - 1).astype(np.int64)
        nb = ix._table.shape
        row = ix._table_flat[((ijk[:, 0] >> BSHIFT) * nb[1] + (ijk[:, 1] >> BSHIFT)) * nb[2] + (ijk[:, 2] >> BSHIFT)]
        m = BLOCK - 1
        off = (((ijk[:, 0] & m) << BSHIFT) + (ijk[:, 1] & m) << BSHIFT) + (ijk[:, 2] & m)
        off += row.astype(np.int64) << (3 * BSHIFT)
        stored = row > 0  # the shared all-void block (row 0) keeps no distances
        codes = np.full(len(p), UNKNOWN, np.int8)
        codes[stored] = self.codes[off[stored]]
        todo = np.flatnonzero(stored & (codes == UNKNOWN))
        step = v / 128.0
        if len(todo):
            voxels, first = np.unique(off[todo], return_index=True)
            centres = ix.origin + (ijk[todo[first]] + 0.5) * v
            _, dc = ix.nearest(centres, ix.max_distance + v)
            new = np.clip(np.rint((dc.astype(np.float64) - ix.max_distance) / step), -127, 127)
            self.codes[voxels] = new.astype(np.int8)  # inf (beyond reach) clips to 127
            codes[stored] = self.codes[off[stored]]
        delta = np.linalg.norm(q - (ijk + 0.5), axis=1) * v + _MARGIN
        c = codes.astype(np.float64)
        known = codes != UNKNOWN
        near = known & ((c + 0.5) * step + delta <= 0)  # dc + |p - c| <= max_distance
        far = known & ((c - 0.5) * step - delta > 0)  # dc - |p - c| > max_distance
        return near, np.flatnonzero(~near & ~far)

    def vertex_bounds(self, p: np.ndarray, which: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Settle the mesh points ``p[which]`` from their nearest vertex.

        A vertex within reach is a surface within reach; a point farther than ``max_distance``
        plus the cover radius from every vertex is out of reach.

        Returns
        -------
        near : bool (len(which),)
            Whether each of those points is surely within reach.
        unsure : int
            The indices (into ``p``) of the points this does not settle.
        """
        ix = self.index
        if self._vertices is None:
            used = np.unique(ix.map.faces)
            self._vertices = (cKDTree(ix.map.points[used]), vertex_cover_radius(ix.map.points, ix.map.faces))
        tree, cover = self._vertices
        dv, _ = tree.query(p[which], distance_upper_bound=ix.max_distance + cover, workers=ix.workers)
        near = dv <= ix.max_distance
        return near, which[~near & np.isfinite(dv)]  # inf: beyond max_distance + cover


def vertex_cover_radius(points: np.ndarray, faces: np.ndarray) -> float:
    """An upper bound on the distance from any point of a triangle to the triangle's nearest
    vertex, over all triangles of a mesh.

    For a triangle that is not obtuse the farthest such point is the circumcentre, at the
    circumradius ``R = abc / (4 area)``; an obtuse (or degenerate) triangle lies inside the
    circle on its longest edge ``L`` as diameter, where every point is within ``L / sqrt(2)``
    of one of that edge's ends.
    """
    v = points.astype(np.float64)[faces]
    e2 = np.stack([((v[:, (i + 1) % 3] - v[:, i]) ** 2).sum(axis=1) for i in range(3)], axis=1)
    e2.sort(axis=1)
    longest = np.sqrt(e2[:, 2])
    obtuse = e2[:, 2] >= e2[:, 0] + e2[:, 1]  # right angles too (R = L / 2 there: both bounds hold)
    area2 = np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1)  # twice the area
    with np.errstate(divide="ignore", invalid="ignore"):
        circum = np.sqrt(e2.prod(axis=1)) / (2.0 * area2)
    radius = np.where(obtuse | ~np.isfinite(circum), longest / np.sqrt(2.0), circum)
    return float(radius.max()) if len(radius) else 0.0
