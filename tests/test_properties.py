"""Property tests (hypothesis): the measures and the transfer methods on generated inputs.

Measures: the fast evaluator equals the authors'-style reference on random maps; every measure
lies in [0, 1]; a map compared with itself scores 1; point order and a shift of both maps by whole
voxels change nothing. Transfer: every method gives labels of the map (or void), void where a
pixel has no depth or no support, purity in [0, 1], one group id per labelled pixel.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from semmatch.evaluate.metrics import MEASURES, compare, compare_dict_loop
from semmatch.io import SemanticMap

pytestmark = pytest.mark.slow

VOXEL = 0.05


@st.composite
def point_maps(draw, min_points: int = 1, max_points: int = 300):
    """A random labelled point map inside a 1 m box (labels 0..12: void, evaluation classes,
    and two classes the measures ignore)."""
    n = draw(st.integers(min_points, max_points))
    seed = draw(st.integers(0, 2**31 - 1))
    rng = np.random.default_rng(seed)
    pts = rng.uniform(0, 1, (n, 3)).astype(np.float32)
    labels = rng.integers(0, 13, n).astype(np.uint8)
    return SemanticMap(pts, labels)


def _perturbed(m: SemanticMap, seed: int, share: float) -> SemanticMap:
    """The same map with a share of its labels changed and a few points moved."""
    rng = np.random.default_rng(seed)
    labels = m.labels.copy()
    flip = rng.random(len(labels)) < share
    labels[flip] = rng.integers(0, 13, int(flip.sum()))
    pts = m.points + (rng.random(m.points.shape) < share) * rng.normal(0, 0.05, m.points.shape).astype(np.float32)
    return SemanticMap(pts, labels)


@settings(max_examples=60, deadline=None)
@given(point_maps(), st.integers(0, 2**31 - 1), st.floats(0.0, 1.0), st.sampled_from(["restrict", "plain"]))
def test_fast_measures_equal_the_reference_evaluator(gt, seed, share, union):
    pred = _perturbed(gt, seed, share)
    fast = compare(gt, pred, VOXEL, union=union, min_overlap=0, densify=False)
    ref = compare_dict_loop(gt, pred, VOXEL, union=union)
    for k in MEASURES:
        assert fast[k] == pytest.approx(ref[k], abs=1e-12), k
        assert 0.0 <= fast[k] <= 1.0


@settings(max_examples=40, deadline=None)
@given(point_maps(min_points=5))
def test_a_map_compared_with_itself_scores_one(m):
    res = compare(m, m, VOXEL, min_overlap=0, densify=False)
    if res["counts"]["gt"]:  # at least one voxel of an evaluation class
        assert all(res[k] == pytest.approx(1.0) for k in MEASURES)


@settings(max_examples=40, deadline=None)
@given(point_maps(), st.integers(0, 2**31 - 1), st.tuples(*[st.integers(-40, 40)] * 3))
def test_point_order_and_whole_voxel_shifts_change_nothing(gt, seed, shift):
    # float-exact setting: points on a 1/1024 m lattice, voxels of 1/16 m, shifts by whole voxels
    v = 1.0 / 16.0
    q = lambda m: SemanticMap(np.round(m.points * 1024) / 1024, m.labels)  # noqa: E731
    gt, pred = q(gt), q(_perturbed(gt, seed, 0.3))
    same = compare(gt, pred, v, min_overlap=0, densify=False)
    order = np.random.default_rng(seed).permutation(len(pred.points))
    d = np.asarray(shift, np.float32) * v
    moved = compare(SemanticMap(gt.points + d, gt.labels), SemanticMap(pred.points[order] + d, pred.labels[order]),
                    v, min_overlap=0, densify=False)
    for k in MEASURES:
        assert moved[k] == same[k], k


# ------------------------------------------------------------------------------------------
# transfer invariants on rendered frames of a generated scene


@pytest.fixture(scope="module")
def scene_and_index():
    from semmatch.sim import generate_scene
    from semmatch.transfer import as_map_index

    scene = generate_scene("bedroom", 11)
    return scene, as_map_index(scene.to_semantic_map())


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.integers(0, 2**31 - 1), st.floats(0.2, 1.6), st.floats(0.0, 0.6))
def test_every_method_gives_map_labels_void_without_support(scene_and_index, seed, height, dropout):
    from semmatch.io import Frame
    from semmatch.io.geometry import DEFAULT_INTRINSICS
    from semmatch.sim import Renderer, make_trajectory
    from semmatch.transfer import METHODS, transfer_frame

    scene, index = scene_and_index
    intr = DEFAULT_INTRINSICS.scaled(96, 72)
    pose = make_trajectory(scene, height, 3, seed=seed % 1000)[1]
    r = Renderer(scene, intr).render(pose)
    rng = np.random.default_rng(seed)
    depth = r.depth.copy()
    depth[rng.random(depth.shape) < dropout] = 0.0  # sensor dropouts
    frame = Frame(r.rgb, depth, r.labels, pose, intr)
    allowed = set(np.unique(scene.labels).tolist()) | {0}
    for name in METHODS:
        res = transfer_frame(name, frame, index)
        assert res.labels.shape == depth.shape and res.labels.dtype == np.uint8
        assert set(np.unique(res.labels).tolist()) <= allowed, name
        assert (res.labels[depth <= 0] == 0).all(), f"{name} labelled pixels without depth"
        assert np.isfinite(res.purity).all() and (res.purity >= 0).all() and (res.purity <= 1 + 1e-6).all(), name
        assert (res.purity[res.labels == 0] == 0).all(), f"{name}: void pixels with a purity"
        if res.groups is not None:
            assert (res.groups[res.labels > 0] >= 0).all(), f"{name}: a labelled pixel in no group"
