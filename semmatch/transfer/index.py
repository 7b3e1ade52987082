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

One module (over 500 lines): the sparse grid's builder, its block store, the lookups and the on-
disk cache all depend on one block layout, which no other module needs to know.
"""

from __future__ import annotations

import os
import warnings
from collections import deque
from concurrent.futures import ThreadPoolExecutor
from functools import partial
from pathlib import Path

import cv2
import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

from ..geometry import Intrinsics, check_pose, pixel_rays
from ..io import SemanticMap
from ..labels import NUM_CLASSES, THING_CLASSES

__all__ = ["MapIndex", "prepare", "load_index", "sample_mesh", "DEFAULT_MAX_DISTANCE", "NO_CACHE_ENV"]

#: Default distance threshold (metres): a lower-view point farther than this from every surface
#: of the upper map has no support and gets label 0. 10 cm is above the depth noise of an RGB-D
#: camera at room range (~1-3 cm) plus the surface error of a TSDF map at 4-5 cm voxels, and
#: below the gap between furniture and the wall/floor it stands near, so unmapped objects
#: (never seen from above) stay void instead of borrowing a neighbour's label.
DEFAULT_MAX_DISTANCE = 0.10

_AMBIGUOUS = 0x80  # grid bit: exact query needed (low 6 bits: the voxel-centre answer)
_SHELL = 0x40  # grid bit: the neighbourhood mixes void and labelled voxels (max_distance shell)
_MIXED = 0x40  # build-time flag (same bit, used before _SHELL is set)
_LABEL_BITS = 0x3F
_EMPTY = 0xFF  # build-time value of a voxel that holds no sample


#: most samples :func:`sample_mesh` may make (a map in millimetres would ask for billions)
MAX_MESH_SAMPLES = 60_000_000


#: voxels along a block edge of the sparse label grid (blocks of BLOCK**3 voxels)
BLOCK = 8
_BSHIFT = 3  # log2(BLOCK)
#: blocks along the x, y, z edges of a chunk: the label grid is computed chunk by chunk (48^3 voxels
#: plus a halo; small chunks keep their distance transforms in cache)
_CHUNK = np.array([6, 6, 6])
#: most blocks the block table may cover (int32 each; the bounding box / BLOCK**3)
MAX_TABLE_BLOCKS = 100_000_000
_BUILD_SAMPLES = 500_000  # mesh samples made (and reduced to voxels) at a time while building
#: most mesh samples an index build may make (made and reduced half a million at a time)
MAX_INDEX_SAMPLES = 2_000_000_000
#: a box of at most this many voxels also keeps its grid dense for lookups (one byte a voxel)
DENSE_LOOKUP_VOXELS = 48_000_000
_BUILD_THREADS = 2  # chunks of the label grid computed at once (SciPy releases the GIL)


def _mesh_sample_chunks(points: np.ndarray, faces: np.ndarray, labels: np.ndarray, spacing: float,
                        chunk_samples: int = _BUILD_SAMPLES):
    """:func:`sample_mesh`'s samples in its order, as a generator of functions that each make one
    piece (samples, labels) when called (so that pieces can be made in worker threads)."""
    v = np.asarray(points, dtype=np.float64)[faces]
    edges = np.stack([v[:, 1] - v[:, 0], v[:, 2] - v[:, 1], v[:, 0] - v[:, 2]], axis=1)
    n_sub = np.maximum(1, np.ceil(np.linalg.norm(edges, axis=2).max(axis=1) / spacing)).astype(np.int64)
    del edges
    flab = np.asarray(labels)[faces]
    for n in np.unique(n_sub):
        sel = np.nonzero(n_sub == n)[0]
        i, j = np.mgrid[0 : n + 1, 0 : n + 1]
        keep = i + j <= n
        bary = np.stack([i[keep], j[keep], n - i[keep] - j[keep]], axis=1).astype(np.float64) / n
        nearest = np.argmax(bary, axis=1)
        chunk = max(1, chunk_samples // len(bary))
        for s in range(0, len(sel), chunk):
            yield partial(_mesh_piece, v, flab, bary, nearest, sel[s : s + chunk])


def _mesh_piece(v, flab, bary, nearest, f) -> tuple[np.ndarray, np.ndarray]:
    """Samples and labels of the faces ``f`` (one piece of :func:`_mesh_sample_chunks`)."""
    return (np.einsum("kc,fcd->fkd", bary, v[f]).reshape(-1, 3).astype(np.float32),
            flab[f][:, nearest].reshape(-1).astype(np.uint8))


def _bounded_map(fn, items, threads: int):
    """``map(fn, items)`` in order on ``threads`` threads, at most ``threads`` items ahead."""
    if threads <= 1:
        yield from map(fn, items)
        return
    pending: deque = deque()
    with ThreadPoolExecutor(threads) as ex:
        for it in items:
            pending.append(ex.submit(fn, it))
            if len(pending) > threads:
                yield pending.popleft().result()
        while pending:
            yield pending.popleft().result()


def sample_mesh(
    points: np.ndarray, faces: np.ndarray, labels: np.ndarray, spacing: float
) -> tuple[np.ndarray, np.ndarray]:
    """Sample a labelled triangle mesh on a barycentric grid.

    Every triangle is split into ``n**2`` sub-triangles with ``n = ceil(longest edge / spacing)``
    and sampled at the grid nodes; a sample takes the label of the triangle vertex with the
    largest barycentric weight (the nearest vertex).

    Parameters
    ----------
    points : float (V,3)
    faces : int (F,3)
    labels : uint8 (V,)
        Per-vertex labels.
    spacing : float
        Largest distance between neighbouring samples along an edge (metres).

    Returns
    -------
    samples : float32 (S,3)
    sample_labels : uint8 (S,)
    """
    if not spacing > 0:
        raise ValueError(f"spacing must be > 0, got {spacing}")
    v = np.asarray(points, dtype=np.float64)[faces]  # (F,3,3)
    edges = np.stack([v[:, 1] - v[:, 0], v[:, 2] - v[:, 1], v[:, 0] - v[:, 2]], axis=1)
    longest = np.linalg.norm(edges, axis=2).max(axis=1)
    n_sub = np.maximum(1, np.ceil(longest / spacing)).astype(np.int64)
    total = int(((n_sub + 1) * (n_sub + 2) // 2).sum())
    if total > MAX_MESH_SAMPLES:  # refuse before allocating (about 26 bytes a sample while built)
        raise ValueError(
            f"sampling the mesh every {spacing:g} m would make {total:,} points (limit {MAX_MESH_SAMPLES:,}, "
            f"about {total * 26 / 2**30:.0f} GiB); its longest edge is {longest.max():.3g}: is the map in "
            "metres (not millimetres)? is the voxel size too small?")
    out_p, out_l = [], []
    flab = np.asarray(labels)[faces]
    for n in np.unique(n_sub):
        sel = np.nonzero(n_sub == n)[0]
        i, j = np.mgrid[0 : n + 1, 0 : n + 1]
        keep = i + j <= n
        bary = np.stack([i[keep], j[keep], n - i[keep] - j[keep]], axis=1).astype(np.float64) / n
        nearest = np.argmax(bary, axis=1)  # vertex of largest weight
        # chunk to bound memory for meshes with many triangles of one size
        chunk = max(1, 4_000_000 // len(bary))
        for s in range(0, len(sel), chunk):
            f = sel[s : s + chunk]
            out_p.append(np.einsum("kc,fcd->fkd", bary, v[f]).reshape(-1, 3).astype(np.float32))
            out_l.append(flab[f][:, nearest].reshape(-1))
    return np.concatenate(out_p), np.concatenate(out_l).astype(np.uint8)


class MapIndex:
    """A semantic map indexed for fast nearest-label lookups (build once, query per frame).

    Parameters
    ----------
    semantic_map : SemanticMap
        Points + labels, or a semantic mesh (``faces``).
    max_distance : float
        Distance threshold in metres: points farther than this from the map read as void (0).
    voxel_size : float
        Edge of the label-grid voxels in metres. Smaller voxels flag fewer points as ambiguous
        (faster lookups) at the cost of memory and build time.
    max_voxels : int
        Memory budget: most voxels the sparse grid may allocate (one byte each, in blocks of
        ``BLOCK**3`` near the map surface). Checked before the blocks are allocated; a map that
        needs more is refused with a ValueError (a map in millimetres, a voxel too small).
    workers : int
        Threads for SciPy KD-tree queries and Open3D queries (1 = single thread).

    Raises
    ------
    ValueError
        Empty map, NaN vertices, label ids outside the category table, or a non-positive
        parameter.

    Examples
    --------
    >>> index = MapIndex(read_map("upper.ply"))            # doctest: +SKIP
    >>> labels = index.lookup(points)                      # doctest: +SKIP
    """

    def __init__(
        self,
        semantic_map: SemanticMap,
        *,
        max_distance: float = DEFAULT_MAX_DISTANCE,
        voxel_size: float = 0.02,
        max_voxels: int = 1_000_000_000,
        workers: int = 1,
    ) -> None:
        if not isinstance(semantic_map, SemanticMap):
            raise TypeError(f"expected a SemanticMap, got {type(semantic_map).__name__}")
        semantic_map.check()
        if semantic_map.labels.max(initial=0) >= NUM_CLASSES:
            raise ValueError(
                f"{semantic_map.source}: label id {int(semantic_map.labels.max())} outside "
                f"0..{NUM_CLASSES - 1}"
            )
        if not (np.isfinite(max_distance) and max_distance > 0):
            raise ValueError(f"max_distance must be > 0, got {max_distance}")
        if not (np.isfinite(voxel_size) and voxel_size > 0):
            raise ValueError(f"voxel_size must be > 0, got {voxel_size}")
        self.map = semantic_map
        self.source = semantic_map.source
        self.max_distance = float(max_distance)
        self.workers = int(workers)
        self.is_mesh = semantic_map.is_mesh
        self.samples = None if self.is_mesh else semantic_map.points
        self.sample_labels = None if self.is_mesh else semantic_map.labels
        self._rc = None
        self._class_trees: dict | None = None  # per-class KD-trees of instance lookups
        self._rays: dict[Intrinsics, tuple[np.ndarray, np.ndarray]] = {}
        self._build_grid(float(voxel_size), int(max_voxels))  # budgets first
        self._tree = None if self.is_mesh else cKDTree(self.samples)

    @classmethod
    def _from_cache(cls, semantic_map: SemanticMap, path, *, map_digest: str, max_distance: float,
                    voxel_size: float, workers: int = 1) -> MapIndex:
        """An index of ``semantic_map`` from a cache file of :func:`load_index` (no grid build).

        The file must be the cache of this map (``map_digest``) at these parameters, its arrays
        must hash to the digest stored with them, and nothing in it may decompress to more than
        the grid the map spans can hold (checked before decompressing).
        """
        self = cls.__new__(cls)
        self.map = semantic_map
        self.source = semantic_map.source
        self.max_distance = float(max_distance)
        self.workers = int(workers)
        self.is_mesh = semantic_map.is_mesh
        self.samples = None if self.is_mesh else semantic_map.points
        self.sample_labels = None if self.is_mesh else semantic_map.labels
        origin, shape, _ = _grid_geometry(*self._bounds(0.7 * voxel_size)[:2], self.max_distance, voxel_size)
        nb = -(-shape // BLOCK)
        n_table = int(np.prod(nb.astype(np.float64)))
        data = _read_cache(path, limit=n_table * (4 + BLOCK**3) + 32 * len(semantic_map.points) + (1 << 20))
        if str(data.pop("map_sha256", "")) != map_digest:
            raise ValueError("it was made for another map or other parameters")
        want = str(data.pop("content_sha256", ""))
        if _arrays_digest(data) != want:
            raise ValueError("its arrays do not match their stored digest (changed after it was written)")
        if (float(data["max_distance"]) != self.max_distance or float(data["voxel_size"]) != float(voxel_size)
                or tuple(int(x) for x in data["shape"]) != tuple(int(x) for x in shape)
                or not np.allclose(data["origin"], origin)):
            raise ValueError("its grid is not the grid of this map")
        if not self.is_mesh and (len(data["samples"]) != len(semantic_map.points)
                                 or not np.array_equal(data["sample_labels"], semantic_map.labels)):
            raise ValueError("the cached samples do not match the map")
        self._tree = None if self.is_mesh else cKDTree(self.samples)
        self._rc = None
        self._class_trees = None
        self._rays = {}
        self.voxel_size = float(data["voxel_size"])
        self.origin = data["origin"].astype(np.float64)
        self.shape = tuple(int(x) for x in data["shape"])
        self._table = data["table"]
        self._blocks = data["blocks"]
        nb = -(-np.asarray(self.shape) // BLOCK)
        if (self._table.shape != tuple(nb) or self._table.dtype != np.int32 or self._blocks.dtype != np.uint8
                or self._blocks.size % BLOCK**3 or not 0 <= self._table.min(initial=0) <= self._table.max(initial=0)
                < self._blocks.size // BLOCK**3):
            raise ValueError(f"block table {self._table.shape} / {self._table.dtype} and {self._blocks.size} block "
                             f"voxels do not fit a grid of {self.shape}")
        self._set_tables()
        self.n_samples = int(data["n_samples"])
        return self

    def __getstate__(self) -> dict:
        state = self.__dict__.copy()
        state["_rc"] = None  # Open3D scenes do not pickle; rebuilt on first use
        state["_dense"] = None  # the expanded grid is rebuilt from the blocks (smaller pickles)
        return state

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self._set_tables()

    # ------------------------------------------------------------------ construction
    def _sample_pieces(self, spacing: float):
        """The map's samples (mesh: :func:`sample_mesh` order) as functions making (points, labels)
        pieces."""
        if self.is_mesh:
            yield from _mesh_sample_chunks(self.map.points, self.map.faces, self.map.labels, spacing)
        else:
            for a in range(0, len(self.samples), _BUILD_SAMPLES):
                yield partial(lambda a: (self.samples[a : a + _BUILD_SAMPLES],
                                         self.sample_labels[a : a + _BUILD_SAMPLES]), a)

    def _bounds(self, spacing: float) -> tuple[np.ndarray, np.ndarray, int]:
        """Lowest and highest sample and the number of samples, before any sample is made."""
        if not self.is_mesh:
            return (self.samples.min(axis=0).astype(np.float64), self.samples.max(axis=0).astype(np.float64),
                    len(self.samples))
        used = np.asarray(self.map.points)[np.unique(self.map.faces)].astype(np.float32)  # the corner samples
        v = np.asarray(self.map.points, dtype=np.float64)[self.map.faces]
        edges = np.stack([v[:, 1] - v[:, 0], v[:, 2] - v[:, 1], v[:, 0] - v[:, 2]], axis=1)
        longest = np.linalg.norm(edges, axis=2).max(axis=1)
        n_sub = np.maximum(1, np.ceil(longest / spacing)).astype(np.int64)
        total = int(((n_sub + 1) * (n_sub + 2) // 2).sum())
        if total > MAX_INDEX_SAMPLES:
            raise ValueError(
                f"{self.source}: sampling the mesh every {spacing:g} m would make {total:,} points (limit "
                f"{MAX_INDEX_SAMPLES:,}); its longest edge is {longest.max():.3g}: is the map in metres (not "
                "millimetres)? is the voxel size too small?")
        return used.min(axis=0).astype(np.float64), used.max(axis=0).astype(np.float64), total

    def _build_grid(self, voxel_size: float, max_voxels: int) -> None:
        """The sparse label grid: only blocks within reach of the map surface are computed and kept.

        Same values as :func:`_dense_grid` (the whole bounding box) in every voxel; budgets are
        checked before anything proportional to the box or the surface is allocated.
        """
        s = voxel_size
        lo, hi, n_samples = self._bounds(0.7 * s)
        self.origin, shape, extent = _grid_geometry(lo, hi, self.max_distance, s)
        self.voxel_size = s
        self.shape = tuple(int(x) for x in shape)
        nb = -(-shape // BLOCK)
        n_table = int(np.prod(nb.astype(np.float64)))
        if n_table > MAX_TABLE_BLOCKS:
            raise ValueError(
                f"{self.source}: the map spans {extent.round(2).tolist()} (map units) and would need a table of "
                f"{n_table:,} blocks of {BLOCK}^3 voxels at {s:g} m (limit {MAX_TABLE_BLOCKS:,}): is the map in "
                "metres (not millimetres)? is the voxel size too small?")
        # occupied voxels: label of the sample nearest to the voxel centre (ties: the lowest label),
        # flagged mixed when the voxel holds samples of several labels; made piece by piece
        def piece(make):
            pts, lab = make()
            key = _voxel_keys(pts, lab, self.origin, s, self.shape)
            key.sort()
            start = np.flatnonzero(np.r_[True, (key[1:] >> 16) != (key[:-1] >> 16)])
            labs = (key & _LABEL_BITS).astype(np.uint8)
            # one row per voxel of the piece: its smallest key << 12 | lowest label << 6 | highest label
            row = key[start].astype(np.uint64) << np.uint64(12)
            row |= np.minimum.reduceat(labs, start).astype(np.uint64) << np.uint64(6)
            row |= np.maximum.reduceat(labs, start).astype(np.uint64)
            return len(pts), row

        rows = []
        self.n_samples = 0
        for n, r in _bounded_map(piece, self._sample_pieces(0.7 * s), _BUILD_THREADS):
            self.n_samples += n
            rows.append(r)
        rows = np.concatenate(rows)
        rows.sort()  # in place: the rows of a voxel together, its smallest key first
        occ_lin, occ_val = [], []
        i, n_rows = 0, len(rows)
        while i < n_rows:  # reduce to one value per voxel a few million rows at a time
            j = min(i + (1 << 22), n_rows)
            if j < n_rows:  # up to the end of the last voxel's rows
                j = int(np.searchsorted(rows, ((rows[j - 1] >> np.uint64(28)) + np.uint64(1)) << np.uint64(28)))
            r = rows[i:j]
            lin = (r >> np.uint64(28)).astype(np.int64)
            start = np.flatnonzero(np.r_[True, lin[1:] != lin[:-1]])
            lmin = np.minimum.reduceat(((r >> np.uint64(6)) & np.uint64(_LABEL_BITS)).astype(np.uint8), start)
            lmax = np.maximum.reduceat((r & np.uint64(_LABEL_BITS)).astype(np.uint8), start)
            occ_lin.append(lin[start])
            occ_val.append(((r[start] >> np.uint64(12)) & np.uint64(_LABEL_BITS)).astype(np.uint8)
                           | np.where(lmin != lmax, _MIXED, 0).astype(np.uint8))
            i = j
        del rows
        occ_lin, occ_val = np.concatenate(occ_lin), np.concatenate(occ_val)
        # blocks within reach: a voxel can be non-void only within floor(max_distance / voxel) + 1
        # voxels of an occupied one (its nearest surface, or a neighbour's, for the flags)
        reach = int(np.floor(self.max_distance / s)) + 1
        # the occupied voxels' values in blocks too (0xFF: not occupied), for gathering chunks;
        # one slab of blocks at a time (occ_lin is sorted, x first)
        bounds = np.searchsorted(occ_lin, np.arange(nb[0] + 1, dtype=np.int64) * BLOCK * shape[1] * shape[2])
        occ_table = np.zeros(tuple(nb), np.int32)
        store = [np.full((1, BLOCK**3), _EMPTY, np.uint8)]
        n_slots, m = 1, BLOCK - 1
        for bx in range(nb[0]):
            a, b = bounds[bx], bounds[bx + 1]
            if a == b:
                continue
            k = np.unravel_index(occ_lin[a:b], self.shape)
            uniq, slot = np.unique((k[1] >> _BSHIFT) * nb[2] + (k[2] >> _BSHIFT), return_inverse=True)
            occ_table[bx].reshape(-1)[uniq] = np.arange(n_slots, n_slots + len(uniq))
            blk = np.full((len(uniq), BLOCK**3), _EMPTY, np.uint8)
            blk[slot, ((k[0] & m) * BLOCK + (k[1] & m)) * BLOCK + (k[2] & m)] = occ_val[a:b]
            store.append(blk)
            n_slots += len(uniq)
        del occ_lin, occ_val
        occ_blocks = np.concatenate(store).reshape(-1, BLOCK, BLOCK, BLOCK)
        del store
        near_blocks = ndimage.binary_dilation(occ_table > 0, np.ones((3, 3, 3), bool), iterations=-(-reach // BLOCK))
        n_alloc = int(near_blocks.sum())
        if n_alloc * BLOCK**3 > max_voxels:
            raise ValueError(
                f"{self.source}: the map's surface needs {n_alloc:,} blocks ({n_alloc * BLOCK**3:,} voxels of "
                f"{s:g} m, limit max_voxels={max_voxels:,}): is the map in metres (not millimetres)? is the "
                "voxel size too small?")
        # chunk by chunk: EDT over the chunk plus a halo that holds every occupied voxel within
        # max_distance of the chunk's voxels and of their neighbours
        pad = reach  # the core's neighbours (1) + the farthest occupied voxel within max_distance of them
        chunk_ids = np.unique(np.stack(np.nonzero(near_blocks), axis=1) // _CHUNK, axis=0)

        def one(c: np.ndarray):
            b0 = c * _CHUNK
            c0 = b0 * BLOCK
            c1 = np.minimum(c0 + _CHUNK * BLOCK, shape)
            e0, e1 = np.maximum(c0 - pad, 0), np.minimum(c1 + pad, shape)
            s0, s1 = e0 >> _BSHIFT, -(-e1 // BLOCK)
            sub = occ_blocks[occ_table[s0[0] : s1[0], s0[1] : s1[1], s0[2] : s1[2]]]
            n = s1 - s0
            vals = sub.transpose(0, 3, 1, 4, 2, 5).reshape(n * BLOCK)
            o0, o1 = e0 - s0 * BLOCK, e1 - s0 * BLOCK
            vals = vals[o0[0] : o1[0], o0[1] : o1[1], o0[2] : o1[2]]
            return c, _label_grid(vals, self.max_distance / s, c0 - e0, c1 - e0, e0, shape)

        table = np.zeros(tuple(nb), np.int32)
        blocks = np.zeros((n_alloc + 1, BLOCK, BLOCK, BLOCK), np.uint8)  # row 0: the all-void block
        n_used = 1
        threads = max(1, min(_BUILD_THREADS, len(chunk_ids)))
        for c, core in _bounded_map(one, chunk_ids, threads):
            if core is None:
                continue
            b0 = c * _CHUNK
            bs = -(-np.asarray(core.shape) // BLOCK)
            full = np.zeros(tuple(bs * BLOCK), np.uint8)
            full[: core.shape[0], : core.shape[1], : core.shape[2]] = core
            cb = full.reshape(bs[0], BLOCK, bs[1], BLOCK, bs[2], BLOCK).transpose(0, 2, 4, 1, 3, 5)
            keep = cb.reshape(bs[0], bs[1], bs[2], -1).any(axis=-1)
            idx = np.nonzero(keep)
            if not len(idx[0]):
                continue
            blocks[n_used : n_used + len(idx[0])] = cb[idx]
            table[b0[0] + idx[0], b0[1] + idx[1], b0[2] + idx[2]] = np.arange(n_used, n_used + len(idx[0]))
            n_used += len(idx[0])
        self._table = table
        blocks.resize((n_used, BLOCK, BLOCK, BLOCK), refcheck=False)  # drop the rows of all-void blocks
        self._blocks = blocks.reshape(-1)
        self._set_tables()

    def _set_tables(self) -> None:
        """Derived lookup tables: the flat block table and, for a box of at most
        :data:`DENSE_LOOKUP_VOXELS`, the grid expanded (one gather per lookup instead of two)."""
        self._table_flat = self._table.reshape(-1)
        self._dense = self.grid.reshape(-1) if np.prod(self.shape) <= DENSE_LOOKUP_VOXELS else None

    @property
    def n_blocks(self) -> int:
        """Allocated blocks of ``BLOCK**3`` voxels (the all-void block not counted)."""
        return len(self._blocks) // BLOCK**3 - 1

    @property
    def nbytes(self) -> int:
        """Bytes held by the label grid (block table, blocks and, for a small box, its dense copy)."""
        return self._table.nbytes + self._blocks.nbytes + (0 if self._dense is None else self._dense.nbytes)

    @property
    def grid(self) -> np.ndarray:
        """The label grid expanded over the whole bounding box (uint8, :attr:`shape`; for tests and
        small maps: it allocates the box)."""
        if getattr(self, "_dense", None) is not None:
            return self._dense.reshape(self.shape).copy()
        nb = self._table.shape
        blocks = self._blocks.reshape(-1, BLOCK, BLOCK, BLOCK)
        out = np.empty(self.shape, np.uint8)
        for bx in range(nb[0]):  # a slab of blocks at a time: the box plus one slab in memory
            slab = blocks[self._table[bx]].transpose(2, 0, 3, 1, 4).reshape(BLOCK, nb[1] * BLOCK, nb[2] * BLOCK)
            x0 = bx * BLOCK
            n = min(BLOCK, self.shape[0] - x0)
            out[x0 : x0 + n] = slab[:n, : self.shape[1], : self.shape[2]]
        return out

    def _values(self, i: np.ndarray, j: np.ndarray, k: np.ndarray, flags: bool = True) -> np.ndarray:
        """Grid values of voxels (i, j, k) (int32 arrays, inside the grid)."""
        nb = self._table.shape
        if self._blocks.size >= 2**31:
            i, j, k = (x.astype(np.int64) for x in (i, j, k))
        t = self._table_flat[((i >> _BSHIFT) * nb[1] + (j >> _BSHIFT)) * nb[2] + (k >> _BSHIFT)]
        m = BLOCK - 1
        off = (((i & m) << _BSHIFT) + (j & m) << _BSHIFT) + (k & m)
        off += t << (3 * _BSHIFT)
        out = self._blocks[off]
        if not flags:
            out &= np.uint8(_LABEL_BITS)
        return out

    def inside(self, points: np.ndarray) -> np.ndarray:
        """Which points lie inside the grid bounds (outside: farther than ``max_distance``
        from every map surface, so without support)."""
        p = np.asarray(points).reshape(-1, 3)
        hi = self.origin + np.asarray(self.shape) * self.voxel_size
        if p.dtype == np.float32 and len(p):
            # one OpenCV pass with the float32 bounds that decide exactly as the float64 ones:
            # p >= lo  <=>  p >= the smallest float32 >= lo;  p < hi  <=>  p <= the largest
            # float32 < hi
            lo32 = self.origin.astype(np.float32)
            lo32 = np.where(lo32 < self.origin, np.nextafter(lo32, np.float32(np.inf)), lo32)
            hi32 = hi.astype(np.float32)
            hi32 = np.where(hi32 >= hi, np.nextafter(hi32, np.float32(-np.inf)), hi32)
            inside = cv2.inRange(np.ascontiguousarray(p).reshape(-1, 1, 3),
                                 tuple(float(x) for x in lo32), tuple(float(x) for x in hi32))
            return inside.reshape(-1) > 0
        ok = np.ones(len(p), bool)
        for a in range(3):
            ok &= (p[:, a] >= self.origin[a]) & (p[:, a] < hi[a])
        return ok

    @property
    def n_points(self) -> int:
        """Number of map points (mesh vertices)."""
        return len(self.map.points)

    @property
    def raycasting_scene(self):
        """Open3D ``RaycastingScene`` of the mesh (built on first use); None for point maps."""
        if not self.is_mesh:
            return None
        if self._rc is None:
            import open3d as o3d

            rc = o3d.t.geometry.RaycastingScene()
            rc.add_triangles(
                o3d.core.Tensor(np.ascontiguousarray(self.map.points, dtype=np.float32)),
                o3d.core.Tensor(np.ascontiguousarray(self.map.faces, dtype=np.uint32)),
            )
            self._rc = rc
        return self._rc

    # ------------------------------------------------------------------ queries
    def nearest(
        self, points: np.ndarray, max_distance: float | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Exact nearest-surface label and distance of each point.

        Meshes: the closest point on the triangles (Open3D ``compute_closest_points``); the label
        is that of the hit triangle's vertex nearest to the closest point. Point maps: the
        nearest map point (``cKDTree``).

        Parameters
        ----------
        points : float (N,3)
            World coordinates.
        max_distance : float, optional
            Points with no surface within this distance get label 0 and distance ``inf`` (this
            also bounds the KD-tree search, which is much faster).

        Returns
        -------
        labels : uint8 (N,)
        distance : float32 (N,)
        """
        p = np.ascontiguousarray(points, dtype=np.float32).reshape(-1, 3)
        if len(p) == 0:
            return np.zeros(0, np.uint8), np.zeros(0, np.float32)
        if not self.is_mesh:
            ub = np.inf if max_distance is None else float(max_distance)
            d, i = self._tree.query(p, distance_upper_bound=ub, workers=self.workers)
            hit = np.isfinite(d)
            lab = np.zeros(len(p), np.uint8)
            lab[hit] = self.map.labels[i[hit]]
            return lab, d.astype(np.float32)
        import open3d as o3d

        ans = self.raycasting_scene.compute_closest_points(o3d.core.Tensor(p), nthreads=self.workers)
        prim = ans["primitive_ids"].numpy().astype(np.int64)
        uv = ans["primitive_uvs"].numpy()
        bary = np.stack([1.0 - uv[:, 0] - uv[:, 1], uv[:, 0], uv[:, 1]], axis=1)
        vert = self.map.faces[prim, np.argmax(bary, axis=1)]
        d = np.linalg.norm(ans["points"].numpy() - p, axis=1).astype(np.float32)
        lab = self.map.labels[vert]
        if max_distance is not None:
            far = d > max_distance
            lab = np.where(far, 0, lab).astype(np.uint8)
            d[far] = np.inf
        return lab, d

    @property
    def has_instances(self) -> bool:
        """True when the indexed map carries an instance layer."""
        return self.map.instances is not None

    def with_instances(self, instances: np.ndarray) -> MapIndex:
        """This index over the same map with another instance layer (the label grid is shared,
        not rebuilt).

        Parameters
        ----------
        instances : int (N,)
            One instance id per map vertex.
        """
        import copy

        m = self.map
        other = copy.copy(self)
        other.map = SemanticMap(m.points, m.labels, colors=m.colors, faces=m.faces, normals=m.normals,
                                source=m.source, instances=instances)
        other._class_trees = None
        return other

    def instances_at(self, points: np.ndarray, labels: np.ndarray) -> np.ndarray:
        """Instance id of the nearest map vertex of each point's own class.

        The panoptic lookup: a point labelled ``c`` takes the instance of the nearest map vertex
        labelled ``c`` within ``max_distance`` (0 when there is none, or when ``c`` is void or a
        stuff class). One KD-tree per class, built on first use.

        Parameters
        ----------
        points : float (N,3)
        labels : uint8 (N,)
            The class each point was given (e.g. by a transfer method).

        Returns
        -------
        int32 (N,)

        Raises
        ------
        ValueError
            The map has no instance layer, or ``points`` and ``labels`` differ in length.
        """
        if self.map.instances is None:
            raise ValueError(
                f"{self.source}: the map has no instance layer (no 'instance' vertex property); "
                "add one with semmatch.panoptic.segment_instances or `semmatch panoptic segment`"
            )
        p = np.asarray(points, dtype=np.float32).reshape(-1, 3)
        lab = np.asarray(labels).reshape(-1)
        if len(p) != len(lab):
            raise ValueError(f"{len(p)} points but {len(lab)} labels")
        out = np.zeros(len(p), np.int32)
        if self._class_trees is None:
            self._class_trees = {}
        for c in np.unique(lab):
            if int(c) not in THING_CLASSES:
                continue
            if int(c) not in self._class_trees:
                verts = np.flatnonzero((self.map.labels == c) & (self.map.instances > 0))
                tree = cKDTree(self.map.points[verts]) if len(verts) else None
                self._class_trees[int(c)] = (tree, self.map.instances[verts])
            tree, inst = self._class_trees[int(c)]
            if tree is None:
                continue
            sel = np.flatnonzero(lab == c)
            d, i = tree.query(p[sel], distance_upper_bound=self.max_distance, workers=self.workers)
            hit = np.isfinite(d)
            out[sel[hit]] = inst[i[hit]]
        return out

    def lookup(self, points: np.ndarray, *, exact: bool = True) -> np.ndarray:
        """Label of the nearest map surface, 0 where it is farther than ``max_distance``.

        Parameters
        ----------
        points : float (N,3)
            World coordinates (non-finite rows read as void).
        exact : bool
            Resolve points in ambiguous voxels (label edges, threshold shell) with an exact
            query. False: take the voxel-centre answer there too (faster; a point within about
            one voxel of a class boundary may take the neighbouring class).

        Returns
        -------
        uint8 (N,)
        """
        p = np.asarray(points, dtype=np.float32).reshape(-1, 3)
        if len(p) == 0:
            return np.zeros(0, np.uint8)
        q = (p - self.origin.astype(np.float32)) / np.float32(self.voxel_size)
        ks = []
        for a in range(3):
            qa = np.nan_to_num(q[:, a], nan=-1.0, posinf=-1.0, neginf=-1.0)
            np.clip(qa, 0, self.shape[a] - 1, out=qa)
            ks.append(qa.astype(np.int32))
        if self._dense is not None:
            out = self._dense[(ks[0].astype(np.int64) * self.shape[1] + ks[1]) * self.shape[2] + ks[2]]
        else:
            out = self._values(*ks)
        return self._resolve(out, lambda sel: p[sel], exact)

    def _gather_depth(
        self, depth: np.ndarray, pose: np.ndarray, intrinsics: Intrinsics, *, flags: bool = True
    ):
        """Grid values of every pixel (with the flag bits, or the voxel-centre labels only) and a
        function giving the world points of selected pixels."""
        T = check_pose(pose)
        rx, ry = self._pixel_rays(intrinsics)
        z = np.asarray(depth, dtype=np.float32)
        if z.shape != intrinsics.shape:
            raise ValueError(f"depth is {z.shape} but the intrinsics say {intrinsics.shape}")
        valid = z > 0  # NaN compares False
        if not (valid | (z == 0)).all() or np.isinf(z).any():
            valid &= np.isfinite(z)
            z = np.where(valid, z, 0).astype(np.float32)
        inv = 1.0 / self.voxel_size
        R = T[:3, :3] * inv
        t = (T[:3, 3] - self.origin) * inv
        dense = self._dense is not None  # one gather: the voxel's linear index, exact in floats
        exact_dtype = np.float32 if np.prod(self.shape) < 2**24 else np.float64
        ks, lin = [], None
        for a in range(3):
            qa = cv2.addWeighted(rx, R[a, 0], ry, R[a, 1], R[a, 2])
            qa = cv2.multiply(qa, z)
            qa += np.float32(t[a])
            np.clip(qa, 0, self.shape[a] - 1, out=qa)
            if not dense:
                ks.append(qa.astype(np.int32))  # truncation = floor (clipped to >= 0)
                continue
            np.floor(qa, out=qa)
            if lin is None:
                lin = qa.astype(exact_dtype, copy=False)
            else:
                lin *= self.shape[a]
                lin += qa
        if dense:
            out = self._dense[lin.astype(np.int64 if exact_dtype is np.float64 else np.int32)]
            if not flags:
                out &= np.uint8(_LABEL_BITS)
        else:
            out = self._values(*ks, flags=flags)
        out[~valid] = 0

        def world(sel: tuple[np.ndarray, ...]) -> np.ndarray:
            zz = z[sel]
            cam = np.stack([rx[sel] * zz, ry[sel] * zz, zz], axis=1)
            return cam @ T[:3, :3].T.astype(np.float32) + T[:3, 3].astype(np.float32)

        return out, world

    def lookup_depth(
        self, depth: np.ndarray, pose: np.ndarray, intrinsics: Intrinsics, *, exact: bool = True
    ) -> np.ndarray:
        """:meth:`lookup` for every pixel of a depth image (the fast path of ``3d-neighborhood``).

        Parameters
        ----------
        depth : float32 (H,W)
            Metres; 0 or non-finite = no measurement (label 0).
        pose : (4,4)
            ``T_world_camera``.
        intrinsics : Intrinsics
        exact : bool
            See :meth:`lookup`.

        Returns
        -------
        uint8 (H,W)
        """
        if not exact:
            return self._gather_depth(depth, pose, intrinsics, flags=False)[0]
        out, world = self._gather_depth(depth, pose, intrinsics)
        return self._resolve(out, world, exact)

    def support_depth(self, depth: np.ndarray, pose: np.ndarray, intrinsics: Intrinsics) -> np.ndarray:
        """Which pixels have a map surface within ``max_distance`` of their 3D point.

        Only voxels of the ``max_distance`` shell need an exact query, so this is cheaper than
        :meth:`lookup_depth`.

        Returns
        -------
        bool (H,W)
        """
        out, world = self._gather_depth(depth, pose, intrinsics)
        sup = (out & np.uint8(_LABEL_BITS)) > 0
        shell = (out & np.uint8(_SHELL)) > 0
        if shell.any():
            sel = np.nonzero(shell)
            _, d = self.nearest(world(sel), self.max_distance)
            sup[sel] = np.isfinite(d)
        return sup

    def _resolve(self, out: np.ndarray, points_of, exact: bool) -> np.ndarray:
        """Replace ambiguous grid answers by exact queries (or by the voxel-centre answer)."""
        amb = out >= _AMBIGUOUS
        if not amb.any():
            out &= np.uint8(_LABEL_BITS)
            return out
        if not exact:
            out &= np.uint8(_LABEL_BITS)
            return out
        sel = np.nonzero(amb)
        lab, _ = self.nearest(points_of(sel), self.max_distance)
        out &= np.uint8(_LABEL_BITS)
        out[sel] = lab
        return out

    def _pixel_rays(self, intr: Intrinsics) -> tuple[np.ndarray, np.ndarray]:
        if intr not in self._rays:
            r = pixel_rays(intr)
            self._rays[intr] = (np.ascontiguousarray(r[..., 0]), np.ascontiguousarray(r[..., 1]))
        return self._rays[intr]

    def __repr__(self) -> str:
        kind = "mesh" if self.is_mesh else "points"
        return (
            f"MapIndex({self.source!r}, {kind}, {self.n_points} vertices, grid {self.shape} at "
            f"{self.voxel_size:.3f} m, max_distance={self.max_distance})"
        )


def _grid_geometry(lo: np.ndarray, hi: np.ndarray, max_distance: float, s: float):
    """Origin, shape (voxels per axis) and extent of the label grid around samples in [lo, hi]."""
    margin = max_distance + 2 * s
    extent = hi - lo + 2 * margin
    return lo - margin, np.ceil(extent / s).astype(np.int64) + 1, extent


def _voxel_keys(points: np.ndarray, labels: np.ndarray, origin: np.ndarray, s: float, shape) -> np.ndarray:
    """Sort keys of samples: voxel (linear index) << 16 | distance to the voxel centre in 1/1024
    voxel << 6 | label; the smallest key of a voxel is its sample nearest to the centre."""
    rel = (points - origin) / s
    k = np.floor(rel).astype(np.int64)
    q = np.minimum(np.linalg.norm(rel - k - 0.5, axis=1) * 1024, 1023).astype(np.int64)
    del rel
    lin = np.ravel_multi_index(k.T, shape)
    return (lin << 16) | (q << 6) | np.asarray(labels, dtype=np.int64)


def _near_and_flags(label_of: np.ndarray, empty: np.ndarray, radius: float, w0=(0, 0, 0), w1=None) -> np.ndarray:
    """Grid values from the occupied voxels' labels: nearest occupied voxel's label (0 beyond
    ``radius`` voxels), with the ambiguous and shell bits; of the window ``w0:w1`` (default: all)."""
    w1 = empty.shape if w1 is None else w1
    win = tuple(slice(a, b) for a, b in zip(w0, w1))
    idx = ndimage.distance_transform_edt(empty, return_distances=False, return_indices=True)[(slice(None), *win)]
    shape = idx.shape[1:]
    near = label_of[tuple(idx)]
    # squared voxel distance to it, in int32 along broadcast axes (SciPy's own distances
    # go through three float64 index volumes: twice the time of the transform itself)
    d2 = np.zeros(shape, dtype=np.int32)
    for a in range(3):
        ax = np.arange(w0[a], w0[a] + shape[a], dtype=np.int32).reshape([-1 if b == a else 1 for b in range(3)])
        step = idx[a].astype(np.int32) - ax
        d2 += step * step
    del idx, step
    # sqrt(d2) > radius, in integers: the largest squared distance whose root is within radius
    limit = int(np.floor(radius)) ** 2
    while np.sqrt(np.float64(limit + 1)) <= radius:
        limit += 1
    near[d2 > limit] = 0
    del d2
    mixed = (near & _MIXED) > 0
    grid = near & ~np.uint8(_MIXED)
    # ambiguous: a mixed nearest voxel, or the 27-neighbourhood disagrees (label edge or the
    # max_distance shell): there the exact query decides
    lo_n, hi_n = ndimage.minimum_filter(grid, size=3), ndimage.maximum_filter(grid, size=3)
    amb = mixed | (lo_n != hi_n)
    shell = (lo_n == 0) & (hi_n > 0)
    grid[amb] |= np.uint8(_AMBIGUOUS)
    grid[shell] |= np.uint8(_SHELL)
    return grid


def _label_grid(vals: np.ndarray, radius: float, c0, c1, e0, shape) -> np.ndarray:
    """Grid values of the core ``c0:c1`` of an extent (origin ``e0`` in the whole grid of ``shape``)
    whose occupied voxels hold their values in ``vals`` (``_EMPTY``: not occupied).

    Only voxels within ``floor(radius) + 1`` voxels of an occupied one can be non-void, so the
    distance transform covers the occupied voxels' bounding box grown by that reach and one
    voxel (their neighbours), not the whole extent."""
    reach = int(np.floor(radius)) + 1
    c0, c1 = np.asarray(c0), np.asarray(c1)
    core = np.zeros(tuple(c1 - c0), np.uint8)
    occ = vals != _EMPTY
    along = [np.flatnonzero(occ.any(axis=tuple(b for b in range(3) if b != a))) for a in range(3)]
    if not len(along[0]):
        return core
    b0 = np.maximum([x[0] - reach - 1 for x in along], 0)
    b1 = np.minimum([x[-1] + reach + 2 for x in along], vals.shape)
    w0 = np.maximum(np.maximum(c0 - 1, 0), b0)  # the core and its neighbours, within that box
    w1 = np.minimum(np.minimum(c1 + 1, vals.shape), b1)
    a0, a1 = np.maximum(w0, c0), np.minimum(w1, c1)
    if (a1 <= a0).any():
        return core
    box = tuple(slice(x, y) for x, y in zip(b0, b1))
    grid = _near_and_flags(vals[box], ~occ[box], radius, w0 - b0, w1 - b0)
    del occ
    core[a0[0] - c0[0] : a1[0] - c0[0], a0[1] - c0[1] : a1[1] - c0[1], a0[2] - c0[2] : a1[2] - c0[2]] = \
        grid[a0[0] - w0[0] : a1[0] - w0[0], a0[1] - w0[1] : a1[1] - w0[1], a0[2] - w0[2] : a1[2] - w0[2]]
    for a in range(3):  # the outer layer of the whole grid stays void (clipped lookups read void)
        if e0[a] + c0[a] == 0:
            core[(slice(None),) * a + (0,)] = 0
        if e0[a] + c1[a] == shape[a]:
            core[(slice(None),) * a + (-1,)] = 0
    return core


def _dense_grid(index: MapIndex) -> np.ndarray:
    """Naive reference of the label grid: one EDT over the whole bounding box (as built before the
    sparse grid; memory and time grow with the box). Same values as ``index.grid``."""
    s, shape = index.voxel_size, index.shape
    best = []
    for make in index._sample_pieces(0.7 * s):
        pts, lab = make()
        best.append(_voxel_keys(pts, lab, index.origin, s, shape))
    key = np.sort(np.concatenate(best))
    start = np.flatnonzero(np.r_[True, (key[1:] >> 16) != (key[:-1] >> 16)])
    labs = (key & _LABEL_BITS).astype(np.uint8)
    mixed = np.minimum.reduceat(labs, start) != np.maximum.reduceat(labs, start)
    vals = np.full(shape, _EMPTY, np.uint8)
    vals.reshape(-1)[key[start] >> 16] = labs[start] | np.where(mixed, _MIXED, 0).astype(np.uint8)
    return _label_grid(vals, index.max_distance / s, np.zeros(3, int), np.asarray(shape), np.zeros(3, int), shape)


_CACHE: list = []


def prepare(
    semantic_map: SemanticMap | MapIndex,
    *,
    max_distance: float | None = None,
    **index_params,
) -> MapIndex:
    """Return a :class:`MapIndex` for ``semantic_map`` (build it, or reuse a given index).

    The last index built from a ``SemanticMap`` object is cached, so calling
    ``transfer(name, frame, semantic_map)`` for many frames indexes the map once.

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
    if _CACHE and _CACHE[0][0] == key and _CACHE[0][1] is semantic_map:
        return _CACHE[0][2]
    index = MapIndex(semantic_map, max_distance=md, **index_params)
    _CACHE[:] = [(key, semantic_map, index)]
    return index


#: version of the index cache files (bump when the grid's meaning changes)
INDEX_CACHE_VERSION = 3
#: environment variable that turns the index cache off (any non-empty value)
NO_CACHE_ENV = "SEMMATCH_NO_INDEX_CACHE"
_CACHED = ("table", "blocks", "origin", "shape", "voxel_size", "max_distance", "n_samples")


def _cache_file(path: Path, max_distance: float, voxel_size: float) -> tuple[Path, str]:
    """``.<map>.index-<key>.npz`` beside the map, and the full key: SHA-256 of its bytes and the parameters."""
    import hashlib

    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    h.update(f"|{max_distance!r}|{voxel_size!r}|{INDEX_CACHE_VERSION}".encode())
    return path.with_name(f".{path.name}.index-{h.hexdigest()[:16]}.npz"), h.hexdigest()


def _arrays_digest(data: dict) -> str:
    """SHA-256 of named arrays: names, dtypes, shapes and bytes, in name order."""
    import hashlib

    h = hashlib.sha256()
    for k in sorted(data):
        a = np.ascontiguousarray(data[k])
        h.update(f"{k}|{a.dtype.str}|{a.shape}|".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def _read_cache(path: Path, *, limit: int) -> dict:
    """The arrays of an ``.npz`` cache; refused when they would decompress to more than ``limit`` bytes."""
    import zipfile

    with zipfile.ZipFile(path) as zf:
        size = sum(info.file_size for info in zf.infolist())
    if size > limit:
        raise ValueError(f"it would decompress to {size:,} bytes, more than the {limit:,} the map's grid can hold")
    with np.load(path, allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


def load_index(path, *, max_distance: float = DEFAULT_MAX_DISTANCE, voxel_size: float = 0.02,
               cache: bool = True, semantic_map: SemanticMap | None = None, **index_params) -> MapIndex:
    """The :class:`MapIndex` of a map file, built once and cached beside it.

    The label grid (the costly part: seconds and most of the memory for a room) is stored as
    ``.<map>.index-<key>.npz`` in the map's folder, keyed by the SHA-256 of the map's bytes and
    the index parameters; a later call with the same map and parameters loads it instead of
    building (the exact queries are rebuilt from the map, cheaply). A cache that cannot be read
    is rebuilt with a warning; a folder that cannot be written just gets no cache.

    Parameters
    ----------
    path : path
        A semantic PLY map (:func:`semmatch.io.read_map`).
    max_distance, voxel_size, **index_params
        As :class:`MapIndex`.
    cache : bool
        Use and write the cache (also off when ``SEMMATCH_NO_INDEX_CACHE`` is set).
    semantic_map : SemanticMap, optional
        The map already read from ``path`` (not read again).

    Returns
    -------
    MapIndex
        Lookups identical to ``MapIndex(read_map(path), ...)``.
    """
    from ..io import atomic_path, read_map

    path = Path(path)
    m = read_map(path) if semantic_map is None else semantic_map
    if not cache or os.environ.get(NO_CACHE_ENV) or index_params.get("max_voxels") is not None:
        return MapIndex(m, max_distance=max_distance, voxel_size=voxel_size, **index_params)
    cf, digest = _cache_file(path, float(max_distance), float(voxel_size))
    if cf.is_file():
        try:
            return MapIndex._from_cache(m, cf, map_digest=digest, max_distance=float(max_distance),
                                        voxel_size=float(voxel_size), **index_params)
        except Exception as e:  # a truncated, foreign, tampered or oversized file: never trusted, rebuilt
            warnings.warn(f"{cf}: unreadable index cache, or not this map's ({type(e).__name__}: {e}); rebuilding it", UserWarning,
                          stacklevel=2)
    index = MapIndex(m, max_distance=max_distance, voxel_size=voxel_size, **index_params)
    arrays = {k: np.asarray(getattr(index, {"table": "_table", "blocks": "_blocks"}.get(k, k))) for k in _CACHED}
    arrays["samples"] = index.samples if index.samples is not None else np.zeros((0, 3), np.float32)
    arrays["sample_labels"] = index.sample_labels if index.sample_labels is not None else np.zeros(0, np.uint8)
    try:
        with atomic_path(cf) as tmp:
            np.savez_compressed(tmp, **arrays, map_sha256=np.asarray(digest),
                                content_sha256=np.asarray(_arrays_digest(arrays)))
    except OSError:  # a read-only folder: no cache
        pass
    return index
