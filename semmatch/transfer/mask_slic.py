"""maskSLIC on a voxel grid (``3d-slic``): scikit-image's SLIC with an exact, faster seeding.

``skimage.segmentation.slic(mask=...)`` seeds its supervoxels with five Lloyd iterations of
``scipy.cluster.vq.kmeans2`` over the occupied voxels. Its nearest-centre search (``vq``) compares
every voxel with every centre, which made a sixth of ``3d-slic``'s time (6.5 of 39 ms a frame,
docs/speed.md). :func:`mask_slic` runs the steps of scikit-image's ``slic`` for a masked
three-channel 3D grid (scikit-image 0.26: normalisation, CIELAB, seeding, the two SLIC passes of
its compiled kernel, connectivity) with two changes. It converts to CIELAB only the occupied
voxels (the only ones the seeding and the masked SLIC passes read). And it replaces that search:
the voxels are grouped in cells of about twice the centres' spacing, a centre is tested for a
cell's voxels only when its distance to the cell's box can beat the farthest corner of the best
centre, and the tested centres are compared in index order with ``vq``'s arithmetic (float64
squared differences summed over the axes in order, strict ``<``). Every centre left out is
strictly farther (bounds taken with a relative margin of 1e-9), so the seeds are bit-identical to
``kmeans2``'s. The CIELAB product on fewer rows could in principle round differently
(:func:`_lab_values`); ``tests/test_mask_slic.py`` compares the supervoxels with ``slic``'s own
on random grids and on rendered frames, and they are identical.

The compiled kernels are scikit-image's private ``_slic_cython`` and
``_enforce_label_connectivity_cython``; where they cannot be imported (another scikit-image), the
public ``slic`` runs instead, with the same labels and its own seeding.
"""

from __future__ import annotations

import functools

import numpy as np

__all__ = ["lloyd", "mask_slic", "seed_centres"]

#: Lloyd iterations of scikit-image's seeding (``kmeans2(..., iter=5)``).
SEED_ITERATIONS = 5


def _kernels():
    """scikit-image's compiled SLIC kernels, or ``None`` where they cannot be imported."""
    try:
        from skimage.segmentation._slic import _enforce_label_connectivity_cython, _slic_cython
    except ImportError:  # pragma: no cover - depends on the installed scikit-image
        return None
    return _slic_cython, _enforce_label_connectivity_cython


def mask_slic(
    grid: np.ndarray,
    mask: np.ndarray,
    *,
    n_segments: int,
    compactness: float,
    max_num_iter: int,
    start_label: int = 1,
) -> np.ndarray:
    """maskSLIC supervoxels of a coloured voxel grid, as ``skimage.segmentation.slic`` gives them.

    Parameters
    ----------
    grid : float (X,Y,Z,3)
        RGB of every cell (any range: normalised by the occupied cells' minimum and maximum, as
        scikit-image does).
    mask : bool (X,Y,Z)
        Occupied cells (at least one).
    n_segments, compactness, max_num_iter, start_label
        As ``skimage.segmentation.slic`` (``sigma=0``, no spacing, connectivity enforced with its
        default size factors).

    Returns
    -------
    int (X,Y,Z)
        Supervoxel of every cell, from ``start_label``; unoccupied cells ``start_label - 1``.

    Raises
    ------
    ValueError
        ``grid`` not (X,Y,Z,3), ``mask`` of another shape, no occupied cell, or non-finite colours.
    """
    grid = np.asarray(grid)
    mask = np.ascontiguousarray(mask, dtype=bool)
    if grid.ndim != 4 or grid.shape[-1] != 3 or mask.shape != grid.shape[:3]:
        raise ValueError(
            f"mask_slic: need an (X,Y,Z,3) grid and an (X,Y,Z) mask, got {grid.shape} and {mask.shape}"
        )
    if not mask.any():
        raise ValueError("mask_slic: the mask has no occupied cell")
    kernels = _kernels()
    if kernels is None:  # pragma: no cover - depends on the installed scikit-image
        from .superpixels import skimage_slic

        return skimage_slic(grid, n_segments=n_segments, compactness=compactness, max_num_iter=max_num_iter,
                            mask=mask, channel_axis=-1, start_label=start_label)
    slic_pass, connect = kernels
    lab = _lab_values(grid, mask)
    dtype = lab.dtype
    mask8 = mask.view("uint8")
    centroids, steps = seed_centres(mask8, int(n_segments))
    spacing = np.ones(3, dtype=dtype)
    segments = np.ascontiguousarray(np.concatenate([centroids, np.zeros((len(centroids), 3))], axis=-1), dtype=dtype)
    step = max(steps)
    # slic scales the whole CIELAB grid by 1 / compactness; its kernel reads occupied cells only
    image = np.zeros(grid.shape, dtype)
    image[mask] = lab * (1.0 / compactness)
    args = (image, mask8, segments, step, int(max_num_iter), spacing, False)
    slic_pass(*args, ignore_color=True, start_label=start_label)  # moves the seeds (in place) by position
    labels = slic_pass(*args, ignore_color=False, start_label=start_label)
    segment_size = mask8.sum() / len(centroids)
    return connect(labels, int(0.5 * segment_size), int(3 * segment_size), start_label=start_label)


def _lab_values(grid: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """The occupied cells' colours normalised by their range and converted to CIELAB (``slic``'s
    preprocessing, in its float type), (V,3) in raster order.

    ``slic`` converts the whole grid; the conversion is per cell, and only the occupied cells are
    converted here (a ninth of the grid on a robot's frame). The colour matrix product then has
    another shape, which could in principle round differently; the tests compare the supervoxels
    with ``slic``'s own on random grids and rendered frames."""
    from skimage._shared.utils import _supported_float_type
    from skimage.color import rgb2lab
    from skimage.util import img_as_float

    image = img_as_float(grid)
    values = image[mask].astype(_supported_float_type(image.dtype), copy=True)
    imin, imax = values.min(), values.max()
    if not (np.isfinite(imin) and np.isfinite(imax)):
        raise ValueError("mask_slic: the occupied cells' colours are not finite")
    values -= imin
    if imax != imin:
        values /= imax - imin
    return rgb2lab(values[None, None])[0, 0]


def seed_centres(mask: np.ndarray, n_centroids: int) -> tuple[np.ndarray, np.ndarray]:
    """The seeds scikit-image's maskSLIC starts from, computed with the pruned search.

    The same steps as ``skimage.segmentation.slic_superpixels._get_mask_centroids``: the occupied
    cells' coordinates in raster order, ``n_centroids`` of them drawn (``RandomState(123)``, no
    replacement) as the initial centres and, where there are more than 100 per centre
    (scikit-image's ``10 ** (mask.ndim - 1)``), a drawn subset of that many as the data; five Lloyd
    iterations (empty clusters keep their centre, as ``kmeans2``); the seeds' spacing as the mean
    axis distance to each seed's nearest other seed.

    Parameters
    ----------
    mask : (X,Y,Z) bool or uint8
    n_centroids : int

    Returns
    -------
    centroids : float64 (K,3)
    steps : float64 (3,)
    """
    from scipy.spatial.distance import pdist, squareform

    coord = np.array(np.nonzero(mask), dtype=float).T
    rng = np.random.RandomState(123)
    idx_full = np.arange(len(coord), dtype=int)
    idx = np.sort(rng.choice(idx_full, min(n_centroids, len(coord)), replace=False))
    # scikit-image takes the mask's dimensions less one (a channel axis the mask does not have)
    n_dense = int((10**2) * n_centroids)
    data = coord[np.sort(rng.choice(idx_full, n_dense, replace=False))] if len(coord) > n_dense else coord
    centroids, _ = lloyd(data, coord[idx], SEED_ITERATIONS)
    dist = squareform(pdist(centroids))
    np.fill_diagonal(dist, np.inf)
    closest = dist.argmin(-1)
    steps = abs(centroids - centroids[closest, :]).mean(0)
    return centroids, steps


def lloyd(data: np.ndarray, centres: np.ndarray, iterations: int) -> tuple[np.ndarray, np.ndarray]:
    """``iterations`` Lloyd iterations from ``centres``: ``scipy.cluster.vq.kmeans2(data, centres,
    iter=iterations)`` for 3D data, bit for bit, with the nearest-centre search pruned per cell.

    Parameters
    ----------
    data : float64 (N,3)
        Points (the pruning groups them in cells of about twice the centres' spacing).
    centres : float64 (K,3)
        Initial centres.
    iterations : int
        At least 1.

    Returns
    -------
    centres : float64 (K,3)
    labels : int32 (N,)
        Nearest centre of every point in the last iteration (the lowest index among equals).
    """
    data = np.ascontiguousarray(data, dtype=np.float64)
    centres = np.ascontiguousarray(centres, dtype=np.float64)
    if data.ndim != 2 or data.shape[1] != 3 or centres.ndim != 2 or centres.shape[1] != 3:
        raise ValueError(f"lloyd: need (N,3) data and (K,3) centres, got {data.shape} and {centres.shape}")
    if int(iterations) < 1 or len(data) == 0 or len(centres) == 0:
        raise ValueError("lloyd: need at least one iteration, one point and one centre")
    if not (np.isfinite(data).all() and np.isfinite(centres).all()):
        raise ValueError("lloyd: data and centres must be finite")
    # cells of about twice the centres' spacing: fewer cells cost fewer bounds, larger ones more
    # candidates (benchmark frames, 6-7 thousand voxels, 128 centres, busy machine: 2.1 ms for the
    # five iterations at 4 voxels a cell, 1.4 at 6-8, 2.2 at 16)
    cell = max(1.0, 2.0 * (len(data) / len(centres)) ** (1.0 / 3.0))
    cells = np.floor((data - data.min(axis=0)) / cell)
    order = np.lexsort(cells.T[::-1])
    starts = np.flatnonzero(np.r_[True, (np.diff(cells[order], axis=0) != 0).any(axis=1), True])
    return _lloyd_kernel()(data, centres, int(iterations), order, starts)


@functools.cache
def _lloyd_kernel():
    """The compiled Lloyd iterations (numba, compiled on first use and cached on disk)."""
    from numba import njit

    @njit(cache=True, nogil=True)
    def kernel(data, code, iterations, order, starts):
        n = data.shape[0]
        k = code.shape[0]
        labels = np.zeros(n, np.int32)
        cand = np.empty(k, np.int64)
        lo = np.empty(3)
        hi = np.empty(3)
        for _ in range(iterations):
            for c in range(len(starts) - 1):
                for a in range(3):
                    lo[a] = np.inf
                    hi[a] = -np.inf
                for s in range(starts[c], starts[c + 1]):
                    i = order[s]
                    for a in range(3):
                        lo[a] = min(lo[a], data[i, a])
                        hi[a] = max(hi[a], data[i, a])
                # the best farthest-corner distance bounds every point's nearest centre
                bound = np.inf
                for j in range(k):
                    far = 0.0
                    for a in range(3):
                        t = max(abs(code[j, a] - lo[a]), abs(code[j, a] - hi[a]))
                        far += t * t
                    bound = min(bound, far)
                bound = bound * (1.0 + 1e-9) + 1e-9
                m = 0
                for j in range(k):
                    near = 0.0
                    for a in range(3):
                        t = max(lo[a] - code[j, a], 0.0, code[j, a] - hi[a])
                        near += t * t
                    if near <= bound:
                        cand[m] = j
                        m += 1
                for s in range(starts[c], starts[c + 1]):
                    i = order[s]
                    best = np.inf
                    lab = 0
                    for q in range(m):
                        j = cand[q]
                        dist = 0.0
                        for a in range(3):
                            diff = code[j, a] - data[i, a]
                            dist += diff * diff
                        if dist < best:
                            best = dist
                            lab = j
                    labels[i] = lab
            sums = np.zeros((k, 3))
            count = np.zeros(k, np.int64)
            for i in range(n):
                j = labels[i]
                for a in range(3):
                    sums[j, a] += data[i, a]
                count[j] += 1
            new = code.copy()
            for j in range(k):
                if count[j] > 0:
                    for a in range(3):
                        new[j, a] = sums[j, a] / count[j]
            code = new
        return code, labels

    return kernel
