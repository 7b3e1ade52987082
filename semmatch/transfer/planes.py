"""RANSAC plane fitting with a seeded, repeatable sampler (the plane step of ``dbscan``).

:func:`ransac_plane` follows Open3D's ``PointCloud.segment_plane``: each hypothesis is the
plane through three distinct random points; a point is an inlier when its distance is below
the threshold; the best hypothesis has the most inliers (ties: the lower RMS distance of its
inliers); the returned plane is refitted to the best hypothesis' inliers by least squares
(the normal is the covariance's eigenvector of the smallest eigenvalue). Unlike Open3D's, the
hypotheses come from a NumPy ``Generator`` and are scored in a compiled loop on one thread,
so a seed gives the same plane on every run and machine (Open3D's parallel sampler does not).
Open3D's early stop (after enough iterations for a 0.99999999 chance of an all-inlier
sample) is kept.
"""

from __future__ import annotations

import functools

import numpy as np

__all__ = ["ransac_plane"]


def ransac_plane(
    points: np.ndarray,
    distance: float,
    iterations: int,
    rng: np.random.Generator,
    probability: float = 0.99999999,
) -> tuple[np.ndarray, np.ndarray]:
    """Fit one plane to ``points`` by RANSAC.

    Parameters
    ----------
    points : float (N,3)
        N >= 3.
    distance : float
        Inlier threshold (metres, > 0).
    iterations : int
        Maximum number of hypotheses (>= 1).
    rng : numpy.random.Generator
        Source of the samples.
    probability : float
        Stop early once an all-inlier sample has been drawn with this probability, given the
        best inlier ratio so far (Open3D's rule); 1 = never stop early.

    Returns
    -------
    model : float64 (4,)
        ``(a, b, c, d)`` with ``a x + b y + c z + d = 0`` and a unit normal; zeros when every
        sample was degenerate (collinear or repeated points).
    inliers : int64 (K,)
        Indices of the points within ``distance`` of the returned plane.

    Raises
    ------
    ValueError
        Fewer than 3 points, a non-positive ``distance`` or ``iterations`` < 1.
    """
    p = np.ascontiguousarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3 or len(p) < 3:
        raise ValueError(f"ransac_plane: need an (N,3) array with N >= 3, got {p.shape}")
    if not distance > 0:
        raise ValueError(f"ransac_plane: distance must be > 0, got {distance}")
    if int(iterations) < 1:
        raise ValueError(f"ransac_plane: iterations must be >= 1, got {iterations}")
    n = len(p)
    samples = rng.integers(0, n, size=(int(iterations), 3))
    best = _kernel()(p, samples, float(distance), float(probability))
    if best[3] == 0.0 and not best[:3].any():
        return np.zeros(4), np.zeros(0, np.int64)
    inl = np.flatnonzero(np.abs(p @ best[:3] + best[3]) < distance)
    if len(inl) >= 3:
        c = p[inl].mean(axis=0)
        q = p[inl] - c
        _, vec = np.linalg.eigh(q.T @ q)
        normal = vec[:, 0]
        model = np.r_[normal, -normal @ c]
    else:
        model = best
    inl = np.flatnonzero(np.abs(p @ model[:3] + model[3]) < distance)
    return model, inl


@functools.cache
def _kernel():
    """The compiled kernel (numba, compiled on first use and cached on disk)."""
    from numba import njit

    @njit(cache=True, nogil=True)
    def kernel(p, samples, distance, probability):
        n = p.shape[0]
        best = np.zeros(4)
        best_fit = -1.0
        best_rmse = np.inf
        limit = samples.shape[0]
        it = 0
        while it < limit:
            i, j, k = samples[it, 0], samples[it, 1], samples[it, 2]
            it += 1
            if i == j or j == k or i == k:
                continue
            ux, uy, uz = p[j, 0] - p[i, 0], p[j, 1] - p[i, 1], p[j, 2] - p[i, 2]
            vx, vy, vz = p[k, 0] - p[i, 0], p[k, 1] - p[i, 1], p[k, 2] - p[i, 2]
            a = uy * vz - uz * vy
            b = uz * vx - ux * vz
            c = ux * vy - uy * vx
            norm = np.sqrt(a * a + b * b + c * c)
            if norm == 0.0:
                continue
            a, b, c = a / norm, b / norm, c / norm
            d = -(a * p[i, 0] + b * p[i, 1] + c * p[i, 2])
            cnt = 0
            err = 0.0
            for t in range(n):
                e = abs(a * p[t, 0] + b * p[t, 1] + c * p[t, 2] + d)
                if e < distance:
                    cnt += 1
                    err += e * e
            fit = cnt / n
            rmse = np.sqrt(err / cnt) if cnt > 0 else np.inf
            if fit > best_fit or (fit == best_fit and rmse < best_rmse):
                best_fit, best_rmse = fit, rmse
                best[0], best[1], best[2], best[3] = a, b, c, d
                if probability < 1.0 and fit > 0.0:
                    w3 = fit * fit * fit
                    if w3 >= 1.0:
                        break
                    need = np.log(1.0 - probability) / np.log(1.0 - w3)
                    if need < limit:
                        limit = max(it, int(np.ceil(need)))
        return best

    return kernel
