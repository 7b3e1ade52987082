"""The sparse label grid of a :class:`~semmatch.transfer.index.MapIndex`, built chunk by chunk.

Every voxel within reach of the map holds the label of the map surface nearest to its centre (0
beyond ``max_distance``), with two flag bits: *ambiguous* (its 26 neighbours do not all hold the
same value: an exact query decides) and *shell* (the neighbourhood mixes void and labelled voxels).
Only blocks of ``BLOCK**3`` voxels near the surface are stored; a block table over the bounding box
points to them (row 0 of the blocks: the all-void block). The map is sampled (a mesh on a
barycentric grid, :func:`semmatch.io.geometry.mesh_sample_pieces`), the samples reduced to occupied
voxels piece by piece, and the distance transforms computed chunk by chunk, so memory follows the
map's surface, not its bounding box (docs/map_index.md). :func:`dense_label_grid` is the naive
reference: one distance transform over the whole box, same values.
"""

from __future__ import annotations

from collections import deque
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from functools import partial

import numpy as np
from scipy import ndimage

from ...io import SemanticMap
from ...io.geometry import mesh_sample_count, mesh_sample_pieces

__all__ = ["LabelGrid", "build_label_grid", "dense_label_grid", "grid_geometry", "sample_bounds", "sample_pieces",
           "BLOCK", "MAX_TABLE_BLOCKS", "MAX_INDEX_SAMPLES"]

AMBIGUOUS = 0x80  # grid bit: exact query needed (low 6 bits: the voxel-centre answer)
SHELL = 0x40  # grid bit: the neighbourhood mixes void and labelled voxels (max_distance shell)
_MIXED = 0x40  # build-time flag (same bit, used before SHELL is set)
LABEL_BITS = 0x3F
_EMPTY = 0xFF  # build-time value of a voxel that holds no sample

#: voxels along a block edge of the sparse label grid (blocks of BLOCK**3 voxels)
BLOCK = 8
BSHIFT = 3  # log2(BLOCK)
#: blocks along the x, y, z edges of a chunk: the label grid is computed chunk by chunk (48^3 voxels
#: plus a halo; small chunks keep their distance transforms in cache)
_CHUNK = np.array([6, 6, 6])
#: most blocks the block table may cover (int32 each; the bounding box / BLOCK**3)
MAX_TABLE_BLOCKS = 100_000_000
_BUILD_SAMPLES = 500_000  # mesh samples made (and reduced to voxels) at a time while building
#: most mesh samples an index build may make (made and reduced half a million at a time)
MAX_INDEX_SAMPLES = 2_000_000_000
_BUILD_THREADS = 2  # chunks of the label grid computed at once (SciPy releases the GIL)


@dataclass
class LabelGrid:
    """A built label grid (what :class:`~semmatch.transfer.index.MapIndex` keeps and caches).

    Attributes
    ----------
    origin : float64 (3,)
        Corner of voxel (0, 0, 0).
    shape : tuple of int
        Voxels along x, y, z.
    voxel_size : float
    table : int32 (shape / BLOCK, rounded up)
        Row of each block in ``blocks`` (0: the all-void block).
    blocks : uint8 (n * BLOCK**3,)
        The stored blocks, flat.
    n_samples : int
        Map samples the grid was built from.
    """

    origin: np.ndarray
    shape: tuple[int, int, int]
    voxel_size: float
    table: np.ndarray
    blocks: np.ndarray
    n_samples: int


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


def _point_piece(points: np.ndarray, labels: np.ndarray, a: int) -> tuple[np.ndarray, np.ndarray]:
    return points[a : a + _BUILD_SAMPLES], labels[a : a + _BUILD_SAMPLES]


def sample_pieces(semantic_map: SemanticMap, spacing: float) -> list:
    """The map's samples as functions making ``(points, labels)`` pieces: a mesh's barycentric grid
    (:func:`semmatch.io.geometry.sample_mesh` order), a point map's points.

    Parameters
    ----------
    semantic_map : SemanticMap
    spacing : float
        Mesh sample spacing (metres).

    Returns
    -------
    list of callables
    """
    m = semantic_map
    if m.is_mesh:
        return mesh_sample_pieces(m.points, m.faces, m.labels, spacing, chunk_samples=_BUILD_SAMPLES,
                                  limit=MAX_INDEX_SAMPLES, source=m.source)
    return [partial(_point_piece, m.points, m.labels, a) for a in range(0, len(m.points), _BUILD_SAMPLES)]


def sample_bounds(semantic_map: SemanticMap, spacing: float) -> tuple[np.ndarray, np.ndarray, int]:
    """Lowest and highest sample and the number of samples, before any sample is made.

    Parameters
    ----------
    semantic_map, spacing
        As :func:`sample_pieces`.

    Returns
    -------
    lo, hi : float64 (3,)
    n_samples : int

    Raises
    ------
    ValueError
        A mesh that would make more than :data:`MAX_INDEX_SAMPLES` samples.
    """
    m = semantic_map
    if not m.is_mesh:
        return m.points.min(axis=0).astype(np.float64), m.points.max(axis=0).astype(np.float64), len(m.points)
    used = np.asarray(m.points)[np.unique(m.faces)].astype(np.float32)  # the corner samples
    total = mesh_sample_count(m.points, m.faces, spacing, limit=MAX_INDEX_SAMPLES, source=m.source)
    return used.min(axis=0).astype(np.float64), used.max(axis=0).astype(np.float64), total


def grid_geometry(lo: np.ndarray, hi: np.ndarray, max_distance: float, s: float):
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


def _piece_rows(make, origin: np.ndarray, s: float, shape: tuple) -> tuple[int, np.ndarray]:
    """One piece's occupied voxels: one row per voxel, its smallest key << 12 | lowest label << 6 |
    highest label (and the piece's number of samples)."""
    pts, lab = make()
    key = _voxel_keys(pts, lab, origin, s, shape)
    key.sort()
    start = np.flatnonzero(np.r_[True, (key[1:] >> 16) != (key[:-1] >> 16)])
    labs = (key & LABEL_BITS).astype(np.uint8)
    row = key[start].astype(np.uint64) << np.uint64(12)
    row |= np.minimum.reduceat(labs, start).astype(np.uint64) << np.uint64(6)
    row |= np.maximum.reduceat(labs, start).astype(np.uint64)
    return len(pts), row


def _occupied_voxels(pieces: list, origin: np.ndarray, s: float, shape: tuple) -> tuple[int, np.ndarray, np.ndarray]:
    """Occupied voxels (sorted linear indices) and their values: label of the sample nearest to the
    voxel centre (ties: the lowest label), flagged mixed when the voxel holds samples of several
    labels; made piece by piece. Also the number of samples."""
    rows = []
    n_samples = 0
    for n, r in _bounded_map(partial(_piece_rows, origin=origin, s=s, shape=shape), pieces, _BUILD_THREADS):
        n_samples += n
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
        lmin = np.minimum.reduceat(((r >> np.uint64(6)) & np.uint64(LABEL_BITS)).astype(np.uint8), start)
        lmax = np.maximum.reduceat((r & np.uint64(LABEL_BITS)).astype(np.uint8), start)
        occ_lin.append(lin[start])
        occ_val.append(((r[start] >> np.uint64(12)) & np.uint64(LABEL_BITS)).astype(np.uint8)
                       | np.where(lmin != lmax, _MIXED, 0).astype(np.uint8))
        i = j
    del rows
    return n_samples, np.concatenate(occ_lin), np.concatenate(occ_val)


def _occupied_blocks(occ_lin: np.ndarray, occ_val: np.ndarray, shape: tuple, nb: np.ndarray):
    """The occupied voxels' values in blocks too (0xFF: not occupied), for gathering chunks; one slab
    of blocks at a time (``occ_lin`` is sorted, x first). Returns the block table and the blocks."""
    bounds = np.searchsorted(occ_lin, np.arange(nb[0] + 1, dtype=np.int64) * BLOCK * shape[1] * shape[2])
    occ_table = np.zeros(tuple(nb), np.int32)
    store = [np.full((1, BLOCK**3), _EMPTY, np.uint8)]
    n_slots, m = 1, BLOCK - 1
    for bx in range(nb[0]):
        a, b = bounds[bx], bounds[bx + 1]
        if a == b:
            continue
        k = np.unravel_index(occ_lin[a:b], shape)
        uniq, slot = np.unique((k[1] >> BSHIFT) * nb[2] + (k[2] >> BSHIFT), return_inverse=True)
        occ_table[bx].reshape(-1)[uniq] = np.arange(n_slots, n_slots + len(uniq))
        blk = np.full((len(uniq), BLOCK**3), _EMPTY, np.uint8)
        blk[slot, ((k[0] & m) * BLOCK + (k[1] & m)) * BLOCK + (k[2] & m)] = occ_val[a:b]
        store.append(blk)
        n_slots += len(uniq)
    return occ_table, np.concatenate(store).reshape(-1, BLOCK, BLOCK, BLOCK)


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
    grid[amb] |= np.uint8(AMBIGUOUS)
    grid[shell] |= np.uint8(SHELL)
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


def _chunk_core(c: np.ndarray, occ_table: np.ndarray, occ_blocks: np.ndarray, shape: np.ndarray, radius: float,
                pad: int):
    """Grid values of chunk ``c``: an EDT over the chunk plus a halo of ``pad`` voxels that holds
    every occupied voxel within ``max_distance`` of the chunk's voxels and of their neighbours."""
    b0 = c * _CHUNK
    c0 = b0 * BLOCK
    c1 = np.minimum(c0 + _CHUNK * BLOCK, shape)
    e0, e1 = np.maximum(c0 - pad, 0), np.minimum(c1 + pad, shape)
    s0, s1 = e0 >> BSHIFT, -(-e1 // BLOCK)
    sub = occ_blocks[occ_table[s0[0] : s1[0], s0[1] : s1[1], s0[2] : s1[2]]]
    n = s1 - s0
    vals = sub.transpose(0, 3, 1, 4, 2, 5).reshape(n * BLOCK)
    o0, o1 = e0 - s0 * BLOCK, e1 - s0 * BLOCK
    vals = vals[o0[0] : o1[0], o0[1] : o1[1], o0[2] : o1[2]]
    return c, _label_grid(vals, radius, c0 - e0, c1 - e0, e0, shape)


def _grid_blocks(occ_table: np.ndarray, occ_blocks: np.ndarray, near_blocks: np.ndarray, n_alloc: int,
                 shape: np.ndarray, radius: float, reach: int) -> tuple[np.ndarray, np.ndarray]:
    """The block table and the flat blocks of the label grid, chunk by chunk over the blocks
    ``near_blocks`` (``n_alloc`` of them) within reach of the surface; all-void blocks dropped."""
    nb = occ_table.shape
    # the core's neighbours (1) + the farthest occupied voxel within max_distance of them
    chunk_ids = np.unique(np.stack(np.nonzero(near_blocks), axis=1) // _CHUNK, axis=0)
    table = np.zeros(tuple(nb), np.int32)
    blocks = np.zeros((n_alloc + 1, BLOCK, BLOCK, BLOCK), np.uint8)  # row 0: the all-void block
    n_used = 1
    threads = max(1, min(_BUILD_THREADS, len(chunk_ids)))
    one = partial(_chunk_core, occ_table=occ_table, occ_blocks=occ_blocks, shape=shape, radius=radius, pad=reach)
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
    blocks.resize((n_used, BLOCK, BLOCK, BLOCK), refcheck=False)  # drop the rows of all-void blocks
    return table, blocks.reshape(-1)


def build_label_grid(semantic_map: SemanticMap, *, max_distance: float, voxel_size: float,
                     max_voxels: int) -> LabelGrid:
    """The sparse label grid of a map: only blocks within reach of the map surface are computed
    and kept.

    Same values as :func:`dense_label_grid` (the whole bounding box) in every voxel; budgets are
    checked before anything proportional to the box or the surface is allocated.

    Parameters
    ----------
    semantic_map : SemanticMap
    max_distance, voxel_size, max_voxels
        As :class:`~semmatch.transfer.index.MapIndex`.

    Returns
    -------
    LabelGrid

    Raises
    ------
    ValueError
        A block table over :data:`MAX_TABLE_BLOCKS`, more than ``max_voxels`` voxels near the
        surface, or a mesh sampling over :data:`MAX_INDEX_SAMPLES` (a map in millimetres, a voxel
        too small).
    """
    s, source = voxel_size, semantic_map.source
    lo, hi, _ = sample_bounds(semantic_map, 0.7 * s)
    origin, shape, extent = grid_geometry(lo, hi, max_distance, s)
    grid_shape = tuple(int(x) for x in shape)
    nb = -(-shape // BLOCK)
    n_table = int(np.prod(nb.astype(np.float64)))
    if n_table > MAX_TABLE_BLOCKS:
        raise ValueError(
            f"{source}: the map spans {extent.round(2).tolist()} (map units) and would need a table of "
            f"{n_table:,} blocks of {BLOCK}^3 voxels at {s:g} m (limit {MAX_TABLE_BLOCKS:,}): is the map in "
            "metres (not millimetres)? is the voxel size too small?")
    n_samples, occ_lin, occ_val = _occupied_voxels(sample_pieces(semantic_map, 0.7 * s), origin, s, grid_shape)
    occ_table, occ_blocks = _occupied_blocks(occ_lin, occ_val, grid_shape, nb)
    del occ_lin, occ_val
    # blocks within reach: a voxel can be non-void only within floor(max_distance / voxel) + 1
    # voxels of an occupied one (its nearest surface, or a neighbour's, for the flags)
    reach = int(np.floor(max_distance / s)) + 1
    near_blocks = ndimage.binary_dilation(occ_table > 0, np.ones((3, 3, 3), bool), iterations=-(-reach // BLOCK))
    n_alloc = int(near_blocks.sum())
    if n_alloc * BLOCK**3 > max_voxels:
        raise ValueError(
            f"{source}: the map's surface needs {n_alloc:,} blocks ({n_alloc * BLOCK**3:,} voxels of "
            f"{s:g} m, limit max_voxels={max_voxels:,}): is the map in metres (not millimetres)? is the "
            "voxel size too small?")
    table, blocks = _grid_blocks(occ_table, occ_blocks, near_blocks, n_alloc, shape, max_distance / s, reach)
    return LabelGrid(origin, grid_shape, s, table, blocks, n_samples)


def dense_label_grid(semantic_map: SemanticMap, *, origin: np.ndarray, shape: tuple, voxel_size: float,
                     max_distance: float) -> np.ndarray:
    """Naive reference of the label grid: one EDT over the whole bounding box (as built before the
    sparse grid; memory and time grow with the box). Same values as ``MapIndex.grid``.

    Parameters
    ----------
    semantic_map : SemanticMap
    origin, shape, voxel_size, max_distance
        The grid's (as :class:`LabelGrid`).

    Returns
    -------
    uint8 (shape)
    """
    s = voxel_size
    best = []
    for make in sample_pieces(semantic_map, 0.7 * s):
        pts, lab = make()
        best.append(_voxel_keys(pts, lab, origin, s, shape))
    key = np.sort(np.concatenate(best))
    start = np.flatnonzero(np.r_[True, (key[1:] >> 16) != (key[:-1] >> 16)])
    labs = (key & LABEL_BITS).astype(np.uint8)
    mixed = np.minimum.reduceat(labs, start) != np.maximum.reduceat(labs, start)
    vals = np.full(shape, _EMPTY, np.uint8)
    vals.reshape(-1)[key[start] >> 16] = labs[start] | np.where(mixed, _MIXED, 0).astype(np.uint8)
    return _label_grid(vals, max_distance / s, np.zeros(3, int), np.asarray(shape), np.zeros(3, int), shape)
