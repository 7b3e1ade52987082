"""semmatch.evaluate.reference: the ground-truth mesh sampled where the lower camera observed it."""

from __future__ import annotations

import numpy as np
import pytest
from scenes import box
from scipy.spatial import cKDTree

from semmatch.evaluate.metrics import compare
from semmatch.evaluate.reference import observed_reference, sample_surface, triangle_labels
from semmatch.fusion import reconstruct
from semmatch.io import Frame, SemanticMap, SequenceWriter, read_map, read_sequence
from semmatch.io.geometry import DEFAULT_INTRINSICS, backproject, look_at, project
from semmatch.sim import Scene, render_frames

INTR = DEFAULT_INTRINSICS.scaled(160, 120)
X, Y, Z = 4.0, 3.0, 2.5
#: the room is moved by half an evaluation voxel so that its axis-aligned faces lie mid-voxel:
#: Open3D's TSDF puts surfaces seen at oblique angles up to ~1 cm off (a face exactly on a
#: voxel boundary would then straddle two voxel layers, a property of the fusion that these
#: tests of the reference should not depend on)
OFF = np.array([0.025, 0.025, 0.025])
SPACING = 0.02
VISIBLE, BEHIND_CAMERA, BEHIND_WALL = 4, 9, 5  # chair in view, bed behind the cameras, table outside


def make_scene() -> Scene:
    """A 4 x 3 x 2.5 m room (walls 1, floor 2, ceiling 3) with three boxes.

    * a box in front of the cameras (label 4),
    * a box behind them, outside every frustum (label 9),
    * a box outside the room behind the wall the cameras face (label 5): it projects into every
      image but the wall hides it.
    """
    grey = (0.8, 0.8, 0.8)
    parts = [
        box((0, 0, -0.05), (X, Y, 0.0), 2, (0.7, 0.6, 0.4), faces=[2, 3]),  # floor (top face)
        box((0, 0, Z), (X, Y, Z + 0.05), 3, grey, faces=[0, 1]),  # ceiling
        box((0, -0.05, 0), (X, 0.0, Z), 1, grey, faces=[6, 7]),  # walls
        box((0, Y, 0), (X, Y + 0.05, Z), 1, grey, faces=[4, 5]),
        box((-0.05, 0, 0), (0.0, Y, Z), 1, grey, faces=[8, 9]),
        box((X, 0, 0), (X + 0.05, Y, Z), 1, grey, faces=[10, 11]),
        box((2.5, 1.2, 0.0), (3.0, 1.7, 0.8), VISIBLE, (0.2, 0.5, 0.8), 1),
        box((0.1, 1.2, 0.0), (0.4, 1.8, 0.5), BEHIND_CAMERA, (0.8, 0.3, 0.2), 2),
        box((X + 0.3, 1.0, 0.5), (X + 0.8, 2.0, 1.5), BEHIND_WALL, (0.3, 0.8, 0.3), 3),
    ]
    scene = Scene.merge(parts, name="reference_room")
    scene.vertices = scene.vertices + OFF.astype(np.float32)
    return scene


def make_poses(n: int = 10) -> np.ndarray:
    """Cameras at 1 m height near the x = 0 wall, looking towards +x (yaw +-35 deg, tilted down)."""
    eye = np.array([1.0, 1.5, 1.0]) + OFF
    poses = []
    for i, yaw in enumerate(np.deg2rad(np.linspace(-35, 35, n))):
        pitch = np.deg2rad((-25.0, -5.0)[i % 2])
        d = np.array([np.cos(yaw) * np.cos(pitch), np.sin(yaw) * np.cos(pitch), np.sin(pitch)])
        poses.append(look_at(eye, eye + d))
    return np.asarray(poses)


@pytest.fixture(scope="module")
def scene() -> Scene:
    return make_scene()


@pytest.fixture(scope="module")
def frames(scene) -> list[Frame]:
    return render_frames(scene, make_poses(), INTR)


@pytest.fixture(scope="module")
def reference(scene, frames) -> SemanticMap:
    return observed_reference(scene, frames, spacing=SPACING)


def region_labels(points: np.ndarray) -> np.ndarray:
    """Label of the surface each point lies on, by position (-1: none, -2: on an edge of two)."""
    p = points.astype(np.float64) - OFF
    eps = 1e-3

    def on_box(lo, hi):
        inside = np.all((p >= np.subtract(lo, eps)) & (p <= np.add(hi, eps)), axis=1)
        return inside & np.any((np.abs(p - lo) < eps) | (np.abs(p - hi) < eps), axis=1)

    regions = {
        2: np.abs(p[:, 2]) < eps,
        3: np.abs(p[:, 2] - Z) < eps,
        1: np.any(np.abs(p[:, :2, None] - [[0, X], [0, Y]]) < eps, axis=(1, 2)),
        VISIBLE: on_box((2.5, 1.2, 0.0), (3.0, 1.7, 0.8)),
        BEHIND_CAMERA: on_box((0.1, 1.2, 0.0), (0.4, 1.8, 0.5)),
        BEHIND_WALL: on_box((X + 0.3, 1.0, 0.5), (X + 0.8, 2.0, 1.5)),
    }
    n = sum(m.astype(int) for m in regions.values())
    lab = np.full(len(p), -1)
    for k, m in regions.items():
        lab[m] = k
    lab[n > 1] = -2
    return lab


# ----------------------------------------------------------------------------- surface sampling
def test_samples_carry_their_triangle_label_and_lie_on_it(scene):
    s = sample_surface(scene, SPACING, seed=1)
    assert s.labels.dtype == np.uint8 and s.points.dtype == np.float32
    np.testing.assert_array_equal(s.labels, scene.labels[s.triangle])
    # each point lies in the plane of its triangle and inside it (barycentric weights >= 0)
    v = scene.vertices[scene.triangles[s.triangle]].astype(np.float64)
    e1, e2, d = v[:, 1] - v[:, 0], v[:, 2] - v[:, 0], s.points - v[:, 0]
    n = np.cross(e1, e2)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    assert np.abs((d * n).sum(1)).max() < 1e-5
    np.testing.assert_allclose(s.face_normals[s.triangle], n, atol=1e-5)
    gram = np.stack([np.stack([(e1 * e1).sum(1), (e1 * e2).sum(1)], 1),
                     np.stack([(e1 * e2).sum(1), (e2 * e2).sum(1)], 1)], 1)
    b12 = np.linalg.solve(gram, np.stack([(d * e1).sum(1), (d * e2).sum(1)], 1)[..., None])[..., 0]
    bary = np.column_stack([1 - b12.sum(1), b12])
    assert bary.min() > -1e-4
    # about one point per spacing**2, on every triangle in proportion to its area
    tv = scene.vertices[scene.triangles].astype(np.float64)
    area = 0.5 * np.linalg.norm(np.cross(tv[:, 1] - tv[:, 0], tv[:, 2] - tv[:, 0]), axis=1)
    assert abs(len(s.points) - area.sum() / SPACING**2) < 0.01 * len(s.points)
    per_tri = np.bincount(s.triangle, minlength=len(area))
    assert np.all(np.abs(per_tri - area / SPACING**2) < 1)  # floor(expected + U)
    # repeatable
    np.testing.assert_array_equal(sample_surface(scene, SPACING, seed=1).points, s.points)


def test_vertex_labelled_mesh_scene_ply_and_scene_agree(scene, tmp_path):
    path = scene.save(tmp_path / "scene.ply")  # per-vertex labels, vertices split per label
    m = read_map(path)
    s = sample_surface(path, SPACING)
    np.testing.assert_array_equal(triangle_labels(m.faces, m.labels), scene.labels)
    np.testing.assert_array_equal(s.labels, scene.labels[s.triangle])
    assert s.source == str(path)
    np.testing.assert_array_equal(sample_surface(m, SPACING).labels, s.labels)


def test_triangle_label_is_the_vertex_majority():
    faces = np.array([[0, 1, 2], [1, 2, 3], [2, 3, 4], [0, 3, 4]])
    vertex_labels = np.array([4, 4, 9, 9, 1], dtype=np.uint8)
    # (4,4,9) -> 4, (4,9,9) -> 9, (9,9,1) -> 9, (4,9,1) tie -> smallest id 1
    np.testing.assert_array_equal(triangle_labels(faces, vertex_labels), [4, 9, 9, 1])
    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [2, 1, 0]], dtype=np.float32)
    s = sample_surface(SemanticMap(pts, vertex_labels, faces=faces), 0.05)
    np.testing.assert_array_equal(s.labels, np.array([4, 9, 9, 1])[s.triangle])


# ----------------------------------------------------------------------------- observation
def test_reference_holds_only_what_the_cameras_saw(scene, frames, reference):
    # premises: the renderer never sees the box behind the cameras nor the one behind the wall,
    # although the latter projects into every image
    seen = np.unique(np.concatenate([f.labels.ravel() for f in frames]))
    assert BEHIND_CAMERA not in seen and BEHIND_WALL not in seen and {1, 2, VISIBLE} <= set(seen)
    centre = np.array([[X + 0.55, 1.5, 1.0]]) + OFF
    for f in frames:
        uv, z = project(centre, INTR, f.pose)
        assert z[0] > 0 and 0 <= uv[0, 0] < INTR.width and 0 <= uv[0, 1] < INTR.height

    ref = reference
    assert not ref.is_mesh and len(ref) > 10_000
    assert np.allclose(np.abs(ref.normals[ref.labels == 2]), [0, 0, 1], atol=1e-6)
    assert "reference_room" in ref.source and "sequence" in ref.source
    labels = set(np.unique(ref.labels))
    assert BEHIND_CAMERA not in labels and BEHIND_WALL not in labels
    assert {1, 2, VISIBLE} <= labels
    # every point carries the label of the surface it lies on
    truth = region_labels(ref.points)
    assert (truth != -1).all() and (truth == -2).mean() < 0.01
    clear = truth > 0
    np.testing.assert_array_equal(ref.labels[clear], truth[clear])
    # only observed points: each lies next to a back-projected depth pixel (pixels are ~3 cm
    # apart at 2 m; a few points on hidden faces within a pixel of a visible crease, e.g. where
    # the box meets the floor, pass the interpolated depth) ...
    bp = np.concatenate([backproject(f.depth, INTR, f.pose)[0] for f in frames])
    dist, _ = cKDTree(bp).query(ref.points, distance_upper_bound=0.5)
    assert np.percentile(dist, 99) < 0.03 and (dist > 0.05).mean() < 5e-4 and dist.max() < 0.15
    # ... and the observed surfaces are covered: the floor and the visible box, in full
    dist, _ = cKDTree(ref.points).query(bp)
    assert np.percentile(dist, 99) < 2 * SPACING
    # the floor behind the visible box (seen from 1 m height, partly hidden) is partly absent
    def shadow(points, labels):
        p = points - OFF
        return ((labels == 2) & (p[:, 0] > 3.05) & (p[:, 0] < 3.3) & (np.abs(p[:, 1] - 1.45) < 0.1)).sum()

    all_samples = sample_surface(scene, SPACING)
    n_shadow = shadow(all_samples.points, all_samples.labels)
    assert n_shadow > 50 and shadow(ref.points, ref.labels) < 0.5 * n_shadow


def test_floor_at_grazing_angles_is_observed_in_full(scene):
    """A robot camera 0.3 m above the floor sees it at 73-82 deg from its normal: the depth
    changes by up to ~20 cm from one pixel to the next, far more than the tolerance; the depth
    interpolated between pixels still finds every floor point (nearest-pixel depth alone keeps
    60% of them here)."""
    eye = np.array([1.0, 0.6, 0.3]) + OFF
    pose = look_at(eye, eye + [1.0, 0.0, 0.0])
    frame = render_frames(scene, [pose], INTR)[0]
    ref = observed_reference(scene, [frame], spacing=SPACING)
    s = sample_surface(scene, SPACING)

    def patch(points, labels):
        p = points - OFF
        return (labels == 2) & (p[:, 0] > 2.0) & (p[:, 0] < 3.0) & (np.abs(p[:, 1] - 0.6) < 0.2)

    n_floor = patch(s.points, s.labels).sum()
    assert n_floor > 800
    assert patch(ref.points, ref.labels).sum() > 0.97 * n_floor


def test_stride_max_depth_and_poses(scene, frames, reference):
    def rows(m):
        return {tuple(r) for r in m.points.tolist()}

    every_other = observed_reference(scene, frames, spacing=SPACING, stride=2)
    assert len(every_other) < len(reference) and rows(every_other) <= rows(reference)
    # max_depth: a point is kept only by a frame where its depth is within reach
    def nearest_depth(points):
        z = np.stack([(points - f.pose[:3, 3]) @ f.pose[:3, 2] for f in frames])
        return np.where(z > 0, z, np.inf).min(axis=0)

    near = observed_reference(scene, frames, spacing=SPACING, max_depth=2.0)
    assert nearest_depth(near.points).max() <= 2.0 + 0.03
    assert (nearest_depth(reference.points) > 2.1).sum() > 1000 and rows(near) < rows(reference)
    # wrong poses in the frames, the true ones passed: the same reference
    shifted = []
    for f in frames:
        pose = f.pose.copy()
        pose[0, 3] += 0.3
        shifted.append(Frame(f.rgb, f.depth, f.labels, pose, INTR, index=f.index))
    with_true = observed_reference(scene, shifted, spacing=SPACING, poses=[f.pose for f in frames])
    np.testing.assert_array_equal(with_true.points, reference.points)
    assert len(observed_reference(scene, shifted, spacing=SPACING)) < 0.9 * len(reference)


def test_sequence_folder_as_input(scene, frames, reference, tmp_path):
    seq_dir = tmp_path / "lower"
    with SequenceWriter(seq_dir, INTR) as w:
        for f in frames:
            w.add(f.rgb, f.depth, f.pose, f.labels)
    ref = observed_reference(scene, read_sequence(seq_dir), spacing=SPACING)
    assert str(seq_dir) in ref.source
    # depth went through millimetre PNGs: nearly the same points
    a, b = ({tuple(r) for r in m.points.tolist()} for m in (ref, reference))
    assert len(a ^ b) < 0.01 * len(b)


# ----------------------------------------------------------------------------- scoring
def test_fused_ground_truth_scores_high_and_a_shift_counts(reference, frames):
    fused = reconstruct(frames, voxel_size=0.04)
    s = compare(reference, fused, 0.05)
    assert s["mean_acc"] > 0.9 and s["color_acc"] > 0.95, {k: s[k] for k in ("jaccard", "sorensen")}
    moved = SemanticMap(fused.points + np.float32([0.1, 0, 0]), fused.labels, faces=fused.faces)
    s_moved = compare(reference, moved, 0.05)
    assert s_moved["mean_acc"] < s["mean_acc"] - 0.1
    assert s_moved["jaccard"] < s["jaccard"] - 0.15
    # the usual reference (the same frames fused with ground-truth labels) cannot see the shift
    same = compare(fused, fused, 0.05)
    assert same["mean_acc"] == 1.0


# ----------------------------------------------------------------------------- bad inputs
def test_bad_inputs_raise(scene, frames):
    with pytest.raises(ValueError, match="no faces"):
        observed_reference(SemanticMap(scene.vertices, np.ones(len(scene.vertices))), frames)
    with pytest.raises(ValueError, match=r"more than the limit of 1,000.*spacing >="):
        observed_reference(scene, frames, max_points=1000)
    with pytest.raises(ValueError, match="no frames"):
        observed_reference(scene, [])
    with pytest.raises(ValueError, match=r"shape \(N,4,4\)"):
        observed_reference(scene, frames, poses=np.zeros((len(frames), 3, 4)))
    with pytest.raises(ValueError, match="3 poses for a sequence of 10 frames"):
        observed_reference(scene, frames, poses=make_poses()[:3])
    bad = make_poses()
    bad[4, 0, 3] = np.nan
    with pytest.raises(ValueError, match="frame 4 pose: holds NaN"):
        observed_reference(scene, frames, poses=bad)
    no_pose = list(frames)
    no_pose[2] = Frame(frames[2].rgb, frames[2].depth, None, None, INTR, index=2)
    with pytest.raises(ValueError, match="frame 2: no pose"):
        observed_reference(scene, no_pose)
    wrong_size = list(frames)
    wrong_size[3] = Frame(frames[3].rgb, frames[3].depth[:, :-1], None, frames[3].pose, INTR, index=3)
    with pytest.raises(ValueError, match="frame 3: depth has shape"):
        observed_reference(scene, wrong_size)
    millimetres = [Frame(f.rgb, f.depth * 1000, None, f.pose, INTR, index=f.index) for f in frames]
    with pytest.raises(ValueError, match="frame 0: median depth"):
        observed_reference(scene, millimetres)
    far_pose = look_at([50.0, 50, 1], [60.0, 50, 1])
    away = [Frame(f.rgb, f.depth, None, far_pose, INTR, index=f.index) for f in frames]
    with pytest.raises(ValueError, match="sequence: no point of scene:reference_room"):
        observed_reference(scene, away, spacing=0.05)
    for kw in ({"spacing": 0.0}, {"tolerance": -1.0}, {"stride": 0}, {"max_depth": 0.0}):
        with pytest.raises(ValueError):
            observed_reference(scene, frames, **kw)
