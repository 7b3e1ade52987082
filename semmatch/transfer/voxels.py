"""Voxelisation of a frame's point cloud on the paper's grid (``3d-slic`` and ``dbscan``).

One compiled pass (numba) gives every point's voxel, the voxels' centroids and, for
``3d-slic``, their mean colours. The arithmetic and the summation order are those of the NumPy
formulation it replaced (float32 keys, float64 sums in point order), so the results are
bit-identical to it (``tests/test_kernels.py`` keeps that NumPy formulation as the
reference).
"""

from __future__ import annotations

import functools

import numpy as np

__all__ = ["voxel_downsample"]


def voxel_downsample(
    points: np.ndarray,
    voxel_size: float,
    rgb: np.ndarray | None = None,
    pixels: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
    """Voxelise a point cloud on the grid ``floor((P - mean(P)) / voxel_size)``.

    Parameters
    ----------
    points : float32 (N,3)
    voxel_size : float
        Voxel edge (metres, > 0).
    rgb : uint8 (H*W,3) or (H,W,3), optional
        The frame's colours; with ``pixels`` (the flat pixel of every point) the voxels' mean
        colours in [0, 1] are returned too.
    pixels : int (N,), optional

    Returns
    -------
    keys : int64 (V,3)
        Voxel coordinates (starting at 0), in the order of their linear index.
    centroids : float32 (V,3)
    voxel_of : int64 (N,)
        Voxel of every point (the trace back to pixels).
    colors : float64 (V,3) or None
        Mean colour of every voxel (only with ``rgb`` and ``pixels``).

    Raises
    ------
    ValueError
        ``voxel_size`` not positive, or ``points`` empty or not (N,3).
    """
    if not voxel_size > 0:
        raise ValueError(f"voxel_size must be > 0, got {voxel_size}")
    p = np.ascontiguousarray(points, dtype=np.float32)
    if p.ndim != 2 or p.shape[1] != 3 or len(p) == 0:
        raise ValueError(f"voxel_downsample: points must be a non-empty (N,3) array, got {p.shape}")
    # the per-axis means as the NumPy formulation computes them (pairwise float64 sums)
    mean = np.array([np.float32(p[:, a].mean(dtype=np.float64)) for a in range(3)], np.float32)
    want = rgb is not None and pixels is not None
    flat_rgb = np.ascontiguousarray(np.asarray(rgb, np.uint8).reshape(-1, 3)) if want else np.zeros((1, 3), np.uint8)
    pix = np.ascontiguousarray(pixels, dtype=np.int64) if want else np.zeros(1, np.int64)
    if want and len(pix) != len(p):
        raise ValueError(f"voxel_downsample: {len(pix)} pixels for {len(p)} points")
    keys, cen, inv, col = _kernel()(p, mean, np.float32(1.0 / voxel_size), flat_rgb, pix, want)
    return keys, cen, inv, (col if want else None)


@functools.cache
def _kernel():
    """The compiled kernel (numba, compiled on first use and cached on disk)."""
    from numba import njit

    @njit(cache=True, nogil=True)
    def kernel(p, mean, inv_v, rgb, pix, want_rgb):
        n = p.shape[0]
        k = np.empty((n, 3), np.int64)
        lo = np.empty(3, np.int64)
        hi = np.empty(3, np.int64)
        for i in range(n):
            for a in range(3):
                q = np.int64(np.floor((p[i, a] - mean[a]) * inv_v))
                k[i, a] = q
                if i == 0 or q < lo[a]:
                    lo[a] = q
                if i == 0 or q > hi[a]:
                    hi[a] = q
        d1 = hi[1] - lo[1] + 1
        d2 = hi[2] - lo[2] + 1
        total = (hi[0] - lo[0] + 1) * d1 * d2
        lin = np.empty(n, np.int64)
        for i in range(n):
            lin[i] = ((k[i, 0] - lo[0]) * d1 + (k[i, 1] - lo[1])) * d2 + (k[i, 2] - lo[2])
        inv = np.empty(n, np.int64)
        uniq = np.empty(n, np.int64)
        v = 0
        if total <= 4 * n + 1_000_000:  # dense counting beats sorting
            ids = np.full(total, -1, np.int64)
            for i in range(n):
                ids[lin[i]] = 0
            for t in range(total):
                if ids[t] == 0:
                    ids[t] = v
                    uniq[v] = t
                    v += 1
            for i in range(n):
                inv[i] = ids[lin[i]]
        else:
            order = np.argsort(lin)
            for s in range(n):
                i = order[s]
                if s == 0 or lin[i] != lin[order[s - 1]]:
                    uniq[v] = lin[i]
                    v += 1
                inv[i] = v - 1
        cnt = np.zeros(v, np.float64)
        sums = np.zeros((v, 3), np.float64)
        csum = np.zeros((v, 3) if want_rgb else (0, 3), np.float64)
        for i in range(n):
            u = inv[i]
            cnt[u] += 1.0
            for a in range(3):
                sums[u, a] += np.float64(p[i, a])
            if want_rgb:
                q = pix[i]
                for a in range(3):
                    csum[u, a] += np.float64(rgb[q, a]) / 255.0
        cen = np.empty((v, 3), np.float32)
        keys = np.empty((v, 3), np.int64)
        for u in range(v):
            for a in range(3):
                cen[u, a] = np.float32(sums[u, a] / cnt[u])
                if want_rgb:
                    csum[u, a] /= cnt[u]
            t = uniq[u]
            keys[u, 2] = t % d2
            t //= d2
            keys[u, 1] = t % d1
            keys[u, 0] = t // d1
        return keys, cen, inv, csum

    return kernel
