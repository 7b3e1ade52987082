"""semmatch.poses.rgbd_odometry: Open3D's multi-scale RGB-D odometry, repeatable from run to run."""

from __future__ import annotations

import numpy as np
import pytest
from test_odometry import rendered_slide

from semmatch.io import depth_to_uint16
from semmatch.poses.odometry import estimate_poses
from semmatch.poses.rgbd_odometry import _pyrdown_depth, multi_scale_odometry, open3d_threads, rgbd_pyramid


@pytest.fixture(scope="module")
def pair():
    frames, gt = rendered_slide(160, 120, n=3)
    return frames[2], frames[0], np.linalg.inv(gt[0]) @ gt[2]  # source, target, true T_target_source


def _open3d(source, target, method: str) -> np.ndarray:
    import open3d as o3d
    import open3d.core as o3c

    odo = o3d.t.pipelines.odometry

    def rgbd(f):
        return o3d.t.geometry.RGBDImage(o3d.t.geometry.Image(o3c.Tensor(np.ascontiguousarray(f.rgb))),
                                        o3d.t.geometry.Image(o3c.Tensor(depth_to_uint16(f.depth))))

    m = {"point-to-plane": odo.Method.PointToPlane, "hybrid": odo.Method.Hybrid}[method]
    with open3d_threads(1):
        res = odo.rgbd_odometry_multi_scale(rgbd(source), rgbd(target), o3c.Tensor(source.intrinsics.K),
                                            o3c.Tensor(np.eye(4)), 1000.0, 5.0,
                                            criteria_list=[odo.OdometryConvergenceCriteria(k) for k in (30, 15, 8)],
                                            method=m)
    return res.transformation.cpu().numpy()


def _pyramids(source, target, rgb: bool = True):
    return [rgbd_pyramid(depth_to_uint16(f.depth), f.rgb if rgb else None, f.intrinsics.K) for f in (source, target)]


def test_point_to_plane_is_open3ds_to_the_bit(pair):
    """Same kernels, same depth pyramid (ours re-implements PyrDownDepth), same stopping rule."""
    source, target, _ = pair
    T, fitness, rmse = multi_scale_odometry(*_pyramids(source, target, rgb=False), np.eye(4))
    assert np.array_equal(T, _open3d(source, target, "point-to-plane"))
    assert 0 < fitness <= 1 and rmse > 0


def test_hybrid_matches_open3d_and_finds_the_true_motion(pair):
    """Only the intensity pyramid's blur differs from Open3D's (OpenCV's, border replicated)."""
    source, target, truth = pair
    T, _, _ = multi_scale_odometry(*_pyramids(source, target), np.eye(4), method="hybrid")
    assert np.abs(T - _open3d(source, target, "hybrid")).max() < 1e-3
    assert np.linalg.norm(T[:3, 3] - truth[:3, 3]) < 0.01


def test_repeated_calls_give_identical_bytes(pair):
    """Open3D's own call differed from call to call with two threads; ours runs on one."""
    pyramids = _pyramids(*pair[:2])
    for method in ("point-to-plane", "hybrid", "intensity"):
        results = {multi_scale_odometry(*pyramids, np.eye(4), method=method)[0].tobytes() for _ in range(4)}
        assert len(results) == 1, method


def test_estimate_poses_is_repeatable():
    frames, gt = rendered_slide(160, 120, n=8)
    a = estimate_poses(frames, init_pose=gt[0])
    b = estimate_poses(frames, init_pose=gt[0])
    assert np.array_equal(a, b)


def test_depth_pyramid_averages_only_depths_close_to_the_centre():
    d = np.full((4, 4), 2.0, np.float32)
    d[0, 1] = 3.0  # beyond the difference threshold of the centre (0, 0): ignored
    d[2, 2] = np.nan  # missing centre of output pixel (1, 1)
    out = _pyrdown_depth(d, diff=0.14)
    assert out.shape == (2, 2)
    assert out[0, 0] == pytest.approx(2.0)
    assert np.isnan(out[1, 1])
    d[0, 1] = 2.1  # within the threshold: averaged in with its Gaussian weight
    assert 2.0 < _pyrdown_depth(d, diff=0.14)[0, 0] < 2.1


def test_unknown_method_and_mismatched_pyramids_are_refused(pair):
    source, target, _ = pair
    ps, pt = _pyramids(source, target)
    with pytest.raises(ValueError, match="method"):
        multi_scale_odometry(ps, pt, np.eye(4), method="colored-icp")
    with pytest.raises(ValueError, match="levels"):
        multi_scale_odometry(ps, pt, np.eye(4), iterations=(10, 5))
    depth_only = rgbd_pyramid(depth_to_uint16(source.depth), None, source.intrinsics.K)
    with pytest.raises(ValueError, match="colour"):
        multi_scale_odometry(depth_only, pt, np.eye(4), method="hybrid")
