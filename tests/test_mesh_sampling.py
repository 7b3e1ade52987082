"""The one mesh sampler of the package (semmatch.io.geometry): the barycentric grid of the map index
and of the measures, the random surface points of the reference and of the trajectories, and the
triangle-label rule; checked against per-triangle loops written here and a few pinned values."""

from __future__ import annotations

import numpy as np
import pytest

from semmatch.io.geometry import (
    mesh_sample_count,
    mesh_sample_pieces,
    sample_mesh,
    sample_mesh_at_random,
    triangle_labels,
)


@pytest.fixture
def mesh(rng):
    """Triangles of many sizes (several subdivision counts) with mixed vertex labels."""
    points = rng.uniform(-1, 1, (40, 3))
    faces = rng.integers(0, 40, (30, 3))
    faces = faces[(faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])]
    return points.astype(np.float32), faces, rng.integers(0, 12, 40).astype(np.uint8)


def _loop_grid(points, faces, labels, spacing, form):
    """The grid samples triangle by triangle in plain Python: (points, nearest-vertex labels,
    majority labels), triangles in order of their subdivision count."""
    v = points.astype(np.float64)[faces]
    n_of = [max(1, int(np.ceil(max(np.linalg.norm(t[a] - t[b]) for a, b in ((1, 0), (2, 1), (0, 2))) / spacing)))
            for t in v]
    out_p, out_near, out_tri = [], [], []
    for n in sorted(set(n_of)):
        for f in [k for k, m in enumerate(n_of) if m == n]:
            a, b, c = v[f]
            lab = labels[faces[f]]
            counts = {x: list(lab).count(x) for x in lab}
            major = [x for x in lab if counts[x] >= 2]
            tri = major[0] if major else min(lab)
            for i in range(n + 1):
                for j in range(n + 1 - i):
                    w = (i / n, j / n, (n - i - j) / n)
                    out_p.append(w[0] * a + w[1] * b + w[2] * c if form == "weights"
                                 else a + w[0] * (b - a) + w[1] * (c - a))
                    out_near.append(lab[int(np.argmax(w))])
                    out_tri.append(tri)
    return np.array(out_p, np.float32), np.array(out_near, np.uint8), np.array(out_tri, np.uint8)


@pytest.mark.parametrize("spacing", [0.05, 0.3, 5.0])
def test_the_grid_sampler_equals_a_per_triangle_loop(mesh, spacing):
    points, faces, labels = mesh
    for form in ("weights", "edges"):
        want_p, near, tri = _loop_grid(points, faces, labels, spacing, form)
        p, lab = sample_mesh(points, faces, labels, spacing, form=form)
        np.testing.assert_allclose(p, want_p, rtol=0, atol=1e-6)
        np.testing.assert_array_equal(lab, near)
        p2, lab2 = sample_mesh(points, faces, labels, spacing, form=form, label="triangle")
        np.testing.assert_array_equal(p2, p)
        np.testing.assert_array_equal(lab2, tri)
        assert len(p) == mesh_sample_count(points, faces, spacing)


def test_pieces_concatenate_to_the_samples_whatever_their_size(mesh):
    points, faces, labels = mesh
    whole = sample_mesh(points, faces, labels, 0.05)
    for chunk in (1, 50, 10**7):
        made = [make() for make in mesh_sample_pieces(points, faces, labels, 0.05, chunk_samples=chunk)]
        for k in range(2):
            np.testing.assert_array_equal(np.concatenate([m[k] for m in made]), whole[k])


def test_a_single_triangle_by_hand():
    points = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)
    p, lab = sample_mesh(points, np.array([[0, 1, 2]]), np.array([1, 2, 3], np.uint8), 1.0)  # n = ceil(sqrt 2) = 2
    # nodes (i, j) = (0,0) (0,1) (0,2) (1,0) (1,1) (2,0): weights (i/2, j/2, 1 - i/2 - j/2) on v0 v1 v2
    np.testing.assert_array_equal(p, [[0, 1, 0], [0.5, 0.5, 0], [1, 0, 0], [0, 0.5, 0], [0.5, 0, 0], [0, 0, 0]])
    assert lab.tolist() == [3, 2, 2, 1, 1, 1]  # nearest vertex; equal weights: the first


def test_sampling_budget_refuses_before_allocating():
    points = np.array([[0, 0, 0], [1000, 0, 0], [0, 1000, 0]], np.float32)  # a metre triangle in millimetres
    with pytest.raises(ValueError, match=r"m\.ply: sampling the mesh every 0\.01 m would make .* millimetres"):
        sample_mesh(points, np.array([[0, 1, 2]]), np.zeros(3, np.uint8), 0.01, source="m.ply")
    with pytest.raises(ValueError, match="spacing must be > 0"):
        mesh_sample_count(points, np.array([[0, 1, 2]]), 0.0)


def test_triangle_labels_majority_and_ties():
    faces = np.array([[0, 1, 2], [3, 4, 5], [6, 7, 8]])
    vertex = np.array([5, 3, 4, 9, 4, 9, 2, 2, 7], np.uint8)
    assert triangle_labels(faces, vertex).tolist() == [3, 9, 2]
    assert triangle_labels(faces, vertex, ties="first").tolist() == [5, 9, 2]
    with pytest.raises(ValueError, match="ties"):
        triangle_labels(faces, vertex, ties="largest")


def test_random_sampler_draws_in_its_documented_order():
    """U per triangle, then r1 and r2 per chunk: rebuilt here from the same seed; pinned values."""
    points = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 2]], np.float64)
    faces = np.array([[0, 1, 2], [0, 1, 3]])
    expected = np.array([2.5, 1.0])
    p, tri = sample_mesh_at_random(points, faces, expected, np.random.default_rng(0))
    assert tri.tolist() == [0, 0, 0, 1] and tri.dtype == np.int32 and p.dtype == np.float32
    np.testing.assert_allclose(p[:3], [[0.07962447, 0.12279472, 0], [0.03477588, 0.09378397, 0],
                                       [0.4115658, 0.49024916, 0]], rtol=0, atol=1e-7)
    rng = np.random.default_rng(0)
    counts = np.floor(expected + rng.random(2)).astype(int)
    t = np.repeat([0, 1], counts)
    v = points[faces][t]
    for chunk in (None, 1, 3):
        got, _ = sample_mesh_at_random(points, faces, expected, np.random.default_rng(0), chunk=chunk,
                                       dtype=np.float64, form="weights")
        rng = np.random.default_rng(0)
        rng.random(2)
        want = []
        for s in range(0, len(t), len(t) if chunk is None else chunk):
            k = len(t[s : s + (len(t) if chunk is None else chunk)])
            sq, r2 = np.sqrt(rng.random(k)), rng.random(k)
            want.append((1 - sq)[:, None] * v[s : s + k, 0] + (sq * (1 - r2))[:, None] * v[s : s + k, 1]
                        + (sq * r2)[:, None] * v[s : s + k, 2])
        np.testing.assert_array_equal(got, np.concatenate(want))
        if chunk is None:  # the same draws as the default chunk: the two forms give one point
            np.testing.assert_allclose(got.astype(np.float32), p, rtol=0, atol=1e-6)
