"""maskSLIC with the pruned seeding (``semmatch.transfer.mask_slic``) against scikit-image and
scipy themselves: the same seeds, the same supervoxels, the same ``3d-slic`` labels."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from scipy.cluster.vq import kmeans2
from scipy.ndimage import binary_dilation
from skimage.segmentation import slic

import semmatch.transfer.methods as methods
from semmatch.io.geometry import DEFAULT_INTRINSICS
from semmatch.sim import render_frames
from semmatch.transfer import MapIndex, transfer_frame
from semmatch.transfer.benchmark import bench_scene
from semmatch.transfer.mask_slic import lloyd, mask_slic, seed_centres
from semmatch.transfer.superpixels import skimage_slic


def _kmeans2(data, init, iterations):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # kmeans2's empty-cluster warning
        return kmeans2(data, init.copy(), iter=iterations)


@pytest.mark.parametrize("kind", ["lattice", "ties", "normal", "far"])
def test_lloyd_is_kmeans2_bit_for_bit(kind):
    """Integer lattices (the voxel coordinates maskSLIC seeds on), a 4x4x4 lattice full of equal
    distances, real-valued and far-off points: centres and labels equal scipy's exactly."""
    rng = np.random.default_rng(["lattice", "ties", "normal", "far"].index(kind))
    for _ in range(25):
        n = int(rng.integers(1, 2500))
        k = int(rng.integers(1, min(n, 150) + 1))
        if kind == "lattice":
            data = rng.integers(0, 50, (n, 3)).astype(float)
        elif kind == "ties":
            data = rng.integers(0, 4, (n, 3)).astype(float)
        elif kind == "normal":
            data = rng.normal(0.0, 7.0, (n, 3))
        else:
            data = rng.normal(1e4, 1.0, (n, 3)) * np.array([1.0, -1.0, 3.0])
        init = data[np.sort(rng.choice(n, k, replace=False))]
        iterations = int(rng.integers(1, 7))
        want_c, want_l = _kmeans2(data, init, iterations)
        got_c, got_l = lloyd(data, init, iterations)
        np.testing.assert_array_equal(got_c, want_c)
        np.testing.assert_array_equal(got_l, want_l)


def test_lloyd_rejects_bad_input():
    pts = np.zeros((4, 3))
    with pytest.raises(ValueError, match="need"):
        lloyd(np.zeros((4, 2)), pts, 5)
    with pytest.raises(ValueError, match="at least one iteration"):
        lloyd(pts, pts, 0)
    with pytest.raises(ValueError, match="finite"):
        lloyd(np.full((4, 3), np.nan), pts, 5)


def test_seeds_are_scikit_images():
    from skimage.segmentation.slic_superpixels import _get_mask_centroids

    rng = np.random.default_rng(5)
    for _ in range(10):
        mask = (rng.random(tuple(int(x) for x in rng.integers(4, 40, 3))) < 0.3).astype(np.uint8)
        n = int(rng.integers(2, 200))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            want = _get_mask_centroids(mask, n, True)
        got = seed_centres(mask, n)
        np.testing.assert_array_equal(got[0], want[0])
        np.testing.assert_array_equal(got[1], want[1])


@pytest.mark.parametrize("sparse", [False, True])
def test_mask_slic_is_scikit_images_slic(sparse):
    """Random grids, scattered or blob-like occupancy, any number of segments, compactness and
    iterations, float32 and float64 colours: the supervoxels equal ``slic``'s exactly."""
    rng = np.random.default_rng(int(sparse))
    for t in range(20):
        dims = tuple(int(x) for x in rng.integers(3, 36, 3))
        if sparse:
            mask = binary_dilation(rng.random(dims) < 0.02, iterations=2)
        else:
            mask = rng.random(dims) < rng.uniform(0.05, 0.7)
        if not mask.any():
            mask[0, 0, 0] = True
        grid = rng.random(dims + (3,)).astype(np.float32 if t % 2 else np.float64)
        params = {
            "n_segments": int(rng.integers(2, 200)),
            "compactness": float(rng.choice([1.0, 10.0, 30.0])),
            "max_num_iter": int(rng.integers(1, 6)),
        }
        want = skimage_slic(grid, mask=mask, channel_axis=-1, start_label=1, **params)
        np.testing.assert_array_equal(mask_slic(grid, mask, **params), want)


def test_mask_slic_single_colour_and_single_cell():
    """One colour (no range to normalise by) and one occupied cell (a zero seed spacing, which
    scikit-image answers with no supervoxel) as scikit-image gives them."""
    grid = np.full((5, 6, 7, 3), 0.5)
    mask = np.zeros((5, 6, 7), bool)
    mask[1:4, 2:5, 3:6] = True
    want = slic(grid, n_segments=4, mask=mask, channel_axis=-1, start_label=1)
    np.testing.assert_array_equal(
        mask_slic(grid, mask, n_segments=4, compactness=10.0, max_num_iter=10), want
    )
    one = np.zeros_like(mask)
    one[2, 2, 2] = True
    want = slic(grid, n_segments=4, mask=one, channel_axis=-1, start_label=1, max_num_iter=3)
    np.testing.assert_array_equal(mask_slic(grid, one, n_segments=4, compactness=10.0, max_num_iter=3), want)


def test_mask_slic_rejects_bad_input():
    with pytest.raises(ValueError, match="need an"):
        mask_slic(np.zeros((4, 4, 3)), np.ones((4, 4), bool), n_segments=2, compactness=10.0, max_num_iter=3)
    with pytest.raises(ValueError, match="no occupied cell"):
        mask_slic(
            np.zeros((4, 4, 4, 3)), np.zeros((4, 4, 4), bool), n_segments=2, compactness=10.0, max_num_iter=3
        )
    grid = np.zeros((4, 4, 4, 3))
    grid[0, 0, 0, 0] = np.nan
    with pytest.raises(ValueError, match="not finite"):
        mask_slic(grid, np.ones((4, 4, 4), bool), n_segments=2, compactness=10.0, max_num_iter=3)


def test_3d_slic_labels_unchanged_on_rendered_frames(monkeypatch):
    """``3d-slic`` on a generated room's robot frames gives the labels, purities and groups it gave
    with scikit-image's ``slic`` (the code before the pruned seeding)."""
    scene, poses = bench_scene(seed=3, n_frames=3)
    frames = render_frames(scene, poses, DEFAULT_INTRINSICS.scaled(320, 240))
    index = MapIndex(scene.to_semantic_map(), voxel_size=0.04)
    new = [transfer_frame("3d-slic", f, index) for f in frames]

    def old(grid, mask, **params):
        return skimage_slic(grid, mask=mask, channel_axis=-1, start_label=1, **params)

    monkeypatch.setattr(methods, "mask_slic", old)
    for f, a in zip(frames, new):
        b = transfer_frame("3d-slic", f, index)
        assert (a.labels > 0).mean() > 0.3
        np.testing.assert_array_equal(a.labels, b.labels)
        np.testing.assert_array_equal(a.purity, b.purity)
        np.testing.assert_array_equal(a.groups, b.groups)
