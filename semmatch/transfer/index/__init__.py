"""The upper map, indexed once: a sparse voxel label grid plus exact nearest-neighbour queries.

:class:`MapIndex` turns a :class:`~semmatch.io.SemanticMap` (points + labels, or a semantic mesh)
into

* a **label grid**: every voxel (default 2 cm) within reach of the map holds the label of the map
  surface nearest to its centre, or 0 (void) when that surface is farther than
  ``max_distance``. A lookup is then one gather per pixel. Voxels whose 26 neighbours do not all
  hold the same value (label boundaries and the ``max_distance`` shell) are flagged *ambiguous*.
  The grid is sparse: only blocks of ``BLOCK**3`` voxels near the surface are stored (a block
  table over the bounding box points to them), and it is built chunk by chunk, so memory follows
  the map's surface, not its bounding box (docs/map_index.md);
* **exact queries** for the points that fall into ambiguous voxels: the closest point on the
  mesh (Open3D ``RaycastingScene.compute_closest_points``, what the authors' code does) or the
  nearest map point (SciPy ``cKDTree``) for point maps.

:meth:`MapIndex.lookup` (``exact=True``) thus returns exactly the nearest-surface label
wherever the answer can differ inside a voxel and the grid answer elsewhere; with
``exact=False`` it returns the voxel-centre answer everywhere (one gather per point: the fast
path of ``3d-neighborhood``; a point within about one voxel of a class edge may take the
neighbouring class).

The parts: :mod:`.label_grid` builds the grid, :mod:`.queries` holds :class:`MapIndex` and its
lookups, :mod:`.reach` settles the support test of the ``max_distance`` shell (memoised
voxel-centre distances, the nearest mesh vertex, then exact queries), :mod:`.cache` gives the
index of a map file, built once and cached (:func:`load_index`). :func:`as_map_index` gives the index of an in-memory map (built once per
map object).
"""

from __future__ import annotations

from ...io import SemanticMap
from ...io.geometry import MAX_MESH_SAMPLES, sample_mesh
from .cache import (
    CACHE_DIR_ENV,
    INDEX_CACHE_VERSION,
    NO_CACHE_ENV,
    index_cache_dir,
    index_cache_path,
    load_index,
)
from .label_grid import BLOCK, MAX_INDEX_SAMPLES, MAX_TABLE_BLOCKS
from .queries import DEFAULT_MAX_DISTANCE, DENSE_LOOKUP_VOXELS, MapIndex

__all__ = ["MapIndex", "as_map_index", "load_index", "index_cache_dir", "index_cache_path", "sample_mesh",
           "DEFAULT_MAX_DISTANCE", "NO_CACHE_ENV", "CACHE_DIR_ENV", "INDEX_CACHE_VERSION", "BLOCK",
           "MAX_MESH_SAMPLES", "MAX_INDEX_SAMPLES", "MAX_TABLE_BLOCKS", "DENSE_LOOKUP_VOXELS"]

_LAST: list = []  # (key, map, index) of the last index built by as_map_index


def as_map_index(
    semantic_map: SemanticMap | MapIndex,
    *,
    max_distance: float | None = None,
    **index_params,
) -> MapIndex:
    """The :class:`MapIndex` of ``semantic_map``: the index itself when given one, else one built.

    The last index built from a ``SemanticMap`` object is kept, so calling
    ``transfer(name, frame, semantic_map)`` for many frames indexes the map once.

    Parameters
    ----------
    semantic_map : SemanticMap or MapIndex
    max_distance : float, optional
        Default :data:`DEFAULT_MAX_DISTANCE`, or the given index's (which must match).
    **index_params
        As :class:`MapIndex`.

    Returns
    -------
    MapIndex

    Raises
    ------
    ValueError
        ``semantic_map`` is an index built for another ``max_distance``.
    TypeError
        Neither a SemanticMap nor a MapIndex.
    """
    if isinstance(semantic_map, MapIndex):
        if max_distance is not None and abs(max_distance - semantic_map.max_distance) > 1e-9:
            raise ValueError(
                f"the index of {semantic_map.source} was built for max_distance="
                f"{semantic_map.max_distance}; build MapIndex(map, max_distance={max_distance}) instead"
            )
        return semantic_map
    if not isinstance(semantic_map, SemanticMap):
        raise TypeError(
            f"expected a SemanticMap or MapIndex, got {type(semantic_map).__name__}"
        )
    md = DEFAULT_MAX_DISTANCE if max_distance is None else float(max_distance)
    key = (id(semantic_map), md, tuple(sorted(index_params.items())))
    if _LAST and _LAST[0][0] == key and _LAST[0][1] is semantic_map:
        return _LAST[0][2]
    index = MapIndex(semantic_map, max_distance=md, **index_params)
    _LAST[:] = [(key, semantic_map, index)]
    return index

