"""The compiled kernels against the library code they replace.

DBSCAN (:mod:`semmatch.transfer.dbscan`) against Open3D ``cluster_dbscan``; voxelisation
(:mod:`semmatch.transfer.voxels`) against its NumPy formulation; RANSAC planes
(:mod:`semmatch.transfer.planes`) on planes with outliers; the map index's float32 bounds test against
the float64 comparison.
"""

from __future__ import annotations

import numpy as np
import pytest

from semmatch.transfer.dbscan import dbscan_labels
from semmatch.transfer.planes import ransac_plane
from semmatch.transfer.voxels import voxel_downsample


def _open3d_dbscan(points, eps, min_points):
    import open3d as o3d

    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(points, np.float64)))
    return np.asarray(pc.cluster_dbscan(float(eps), int(min_points)), np.int64)


def _cloud(seed: int) -> tuple[np.ndarray, float, int]:
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 600))
    p = rng.random((n, 3)) * rng.uniform(0.2, 2.0)
    if seed % 3 == 0:  # a lattice: many pairs exactly on the eps boundary or at equal distances
        p = np.round(p * 20) / 20
    if seed % 5 == 0:  # duplicated points
        p = np.concatenate([p, p[: n // 3]])
    if seed % 4 == 0:  # separated blobs, so that clusters and border points compete
        p = np.concatenate([p, p[: n // 2] + rng.uniform(0.5, 3.0, 3)])
    eps = 0.1 if seed % 7 == 0 else float(rng.uniform(0.03, 0.3))
    return p, eps, int(rng.integers(1, 15))


@pytest.mark.parametrize("block", range(4))
def test_dbscan_labels_equal_open3d(block):
    for seed in range(block * 100, block * 100 + 100):
        p, eps, m = _cloud(seed)
        np.testing.assert_array_equal(dbscan_labels(p, eps, m), _open3d_dbscan(p, eps, m), err_msg=f"seed {seed}")


def test_dbscan_labels_equal_open3d_on_surfaces():
    """Voxel centroids of planes and boxes, the clouds the ``dbscan`` method clusters."""
    rng = np.random.default_rng(1)
    g = np.stack(np.meshgrid(np.arange(0, 3, 0.04), np.arange(0, 2, 0.04), indexing="ij"), -1).reshape(-1, 2)
    floor = np.c_[g, np.zeros(len(g))]
    wall = np.c_[g[:, 0], np.zeros(len(g)), g[:, 1]]
    box = rng.uniform([1, 1, 0], [1.4, 1.3, 0.5], (800, 3))
    p = np.concatenate([floor, wall, box]) + rng.normal(0, 0.004, (len(floor) + len(wall) + 800, 3))
    for eps, m in [(0.1, 10), (0.05, 4), (0.1, 1), (0.2, 40)]:
        np.testing.assert_array_equal(dbscan_labels(p, eps, m), _open3d_dbscan(p, eps, m))


def test_dbscan_labels_equal_open3d_in_a_sparse_box():
    """Blobs tens of metres apart at a small eps: too many cells for the dense cell table, so
    the neighbouring cells come from binary searches; the labels are Open3D's all the same."""
    rng = np.random.default_rng(2)
    centres = rng.uniform(-40, 40, (6, 3))
    p = np.concatenate([c + rng.normal(0, 0.05, (150, 3)) for c in centres])
    eps = 0.03
    assert np.prod(np.ptp(p, axis=0) / eps) > 8 * len(p) + 1_000_000  # the sparse path
    np.testing.assert_array_equal(dbscan_labels(p, eps, 3), _open3d_dbscan(p, eps, 3))
    assert dbscan_labels(p, eps, 3).max() >= 5


def test_dbscan_labels_edge_cases():
    assert dbscan_labels(np.zeros((0, 3)), 0.1, 10).shape == (0,)
    np.testing.assert_array_equal(dbscan_labels(np.zeros((1, 3)), 0.1, 1), [0])
    np.testing.assert_array_equal(dbscan_labels(np.zeros((1, 3)), 0.1, 2), [-1])
    # exactly eps apart: not neighbours (strict, as Open3D)
    np.testing.assert_array_equal(dbscan_labels(np.array([[0, 0, 0], [0.5, 0, 0]]), 0.5, 1), [0, 1])
    for bad, msg in [((np.zeros((3, 2)), 0.1, 1), "N,3"), ((np.zeros((3, 3)), 0.0, 1), "eps"),
                     ((np.zeros((3, 3)), 0.1, 0), "min_points"), ((np.full((3, 3), np.nan), 0.1, 1), "NaN"),
                     ((np.array([[0, 0, 0], [1e9, 1e9, 1e9]]), 1e-9, 1), "units")]:
        with pytest.raises(ValueError, match=msg):
            dbscan_labels(*bad)


def _numpy_voxel_downsample(points, voxel_size):
    """The NumPy formulation the kernel replaced (float32 keys, float64 bincount sums)."""
    cols = [np.ascontiguousarray(points[:, a], dtype=np.float32) for a in range(3)]
    inv_v = np.float32(1.0 / voxel_size)
    ks, dims = [], []
    for c in cols:
        k = np.floor((c - np.float32(c.mean(dtype=np.float64))) * inv_v).astype(np.int64)
        k -= k.min()
        ks.append(k)
        dims.append(int(k.max()) + 1)
    lin = (ks[0] * dims[1] + ks[1]) * dims[2] + ks[2]
    uniq, inv = np.unique(lin, return_inverse=True)
    cnt = np.bincount(inv).astype(np.float64)
    cen = np.empty((len(uniq), 3), np.float32)
    for a, c in enumerate(cols):
        cen[:, a] = np.bincount(inv, c, minlength=len(uniq)) / cnt
    return np.stack(np.unravel_index(uniq, dims), axis=1), cen, inv, cnt


@pytest.mark.parametrize("spread", [3.0, 500.0])  # dense counting / sorting path
def test_voxel_downsample_equals_numpy(spread):
    rng = np.random.default_rng(int(spread))
    pts = (rng.random((50_000, 3)) * [spread, 2.0, 1.5] - 0.7).astype(np.float32)
    pts[::7] = pts[1::7][: len(pts[::7])]  # shared voxels
    pixels = rng.permutation(200_000)[: len(pts)]
    rgb = rng.integers(0, 256, (200_000, 3), dtype=np.uint8)
    for vs in (0.04, 0.1):
        keys, cen, inv, col = voxel_downsample(pts, vs, rgb, pixels)
        k0, c0, i0, cnt = _numpy_voxel_downsample(pts, vs)
        np.testing.assert_array_equal(keys, k0)
        np.testing.assert_array_equal(cen, c0)
        np.testing.assert_array_equal(inv, i0)
        ref = rgb[pixels].astype(np.float64) / 255.0
        np.testing.assert_array_equal(col, np.stack([np.bincount(i0, ref[:, c]) / cnt for c in range(3)], axis=1))
        assert voxel_downsample(pts, vs)[3] is None
    with pytest.raises(ValueError, match="voxel_size"):
        voxel_downsample(pts, 0.0)
    with pytest.raises(ValueError, match="non-empty"):
        voxel_downsample(np.zeros((0, 3), np.float32), 0.1)


def test_ransac_plane_finds_the_plane_and_repeats():
    rng = np.random.default_rng(0)
    n = np.array([0.2, -0.3, 0.93])
    n /= np.linalg.norm(n)
    a, b = np.linalg.svd(n[None])[2][1:]  # two directions in the plane
    uv = rng.uniform(-1, 1, (600, 2))
    plane = uv[:, :1] * a + uv[:, 1:] * b + n * 0.5 + rng.normal(0, 0.003, (600, 1)) * n
    pts = np.concatenate([plane, rng.uniform(-1, 1, (400, 3))])
    model, inl = ransac_plane(pts, 0.02, 300, np.random.default_rng(3))
    assert abs(abs(model[:3] @ n) - 1) < 1e-3 and abs(abs(model[3]) - 0.5) < 5e-3
    assert np.isin(np.arange(600), inl).mean() > 0.99
    again, inl2 = ransac_plane(pts, 0.02, 300, np.random.default_rng(3))
    np.testing.assert_array_equal(again, model)
    np.testing.assert_array_equal(inl2, inl)
    line = np.c_[np.linspace(0, 1, 20), np.zeros(20), np.zeros(20)]
    model, inl = ransac_plane(line, 0.01, 50, np.random.default_rng(0))  # collinear: no plane
    assert not model.any() and len(inl) == 0
    with pytest.raises(ValueError, match="N >= 3"):
        ransac_plane(line[:2], 0.01, 10, np.random.default_rng(0))
    with pytest.raises(ValueError, match="distance"):
        ransac_plane(line, 0.0, 10, np.random.default_rng(0))


def test_index_inside_float32_matches_float64_bounds():
    from scenes import furnished_room

    from semmatch.transfer import MapIndex

    index = MapIndex(furnished_room(0).to_semantic_map())
    lo = index.origin
    hi = lo + np.asarray(index.shape) * index.voxel_size
    rng = np.random.default_rng(0)
    pts = [rng.uniform(lo - 0.5, hi + 0.5, (20_000, 3)).astype(np.float32)]
    mid = ((lo + hi) / 2).astype(np.float32)
    for a in range(3):
        for bound in (lo[a], hi[a]):
            f = np.float32(bound)
            for v in (np.nextafter(f, np.float32(-np.inf)), f, np.nextafter(f, np.float32(np.inf))):
                q = mid.copy()
                q[a] = v
                pts.append(q[None])
    p = np.concatenate(pts + [np.full((1, 3), np.nan, np.float32)])
    want = np.all((p >= lo) & (p < hi), axis=1)
    np.testing.assert_array_equal(index.inside(p), want)
    np.testing.assert_array_equal(index.inside(p.astype(np.float64)), want)
