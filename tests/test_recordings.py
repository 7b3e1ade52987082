"""semmatch.recordings: TUM RGB-D folders (association, ground truth, intrinsics, bad input)."""

from __future__ import annotations

import numpy as np
import pytest

from semmatch.geometry import look_at
from semmatch.io import write_depth, write_image, write_tum
from semmatch.recordings import TUM_INTRINSICS, associate, interpolate_poses, is_tum_rgbd, read_tum_rgbd

H, W = 48, 64


def write_tum_folder(root, rgb_t, depth_t, gt_t=None, *, depth_m=2.0, depth_scale=5000.0):
    """A small TUM RGB-D folder: constant-colour frames, flat depth, optional ground truth."""
    root.mkdir(parents=True, exist_ok=True)
    lines = {"rgb": ["# color images", "# timestamp filename"], "depth": ["# depth maps"]}
    for t in rgb_t:
        name = f"rgb/{t:.6f}.png"
        write_image(root / name, np.full((H, W, 3), int(t * 10) % 255, np.uint8))
        lines["rgb"].append(f"{t:.6f} {name}")
    for t in depth_t:
        name = f"depth/{t:.6f}.png"
        write_depth(root / name, np.full((H, W), depth_m, np.float32), depth_scale)
        lines["depth"].append(f"{t:.6f} {name}")
    for k, v in lines.items():
        (root / f"{k}.txt").write_text("\n".join(v) + "\n")
    if gt_t is not None:
        poses = np.stack([look_at([t, 0.0, 1.0], [t, 5.0, 1.0]) for t in gt_t])  # x = time
        write_tum(root / "groundtruth.txt", gt_t, poses)


def test_reads_associated_frames_with_interpolated_ground_truth(tmp_path):
    rgb_t = 100.0 + np.arange(6) * 0.1
    depth_t = rgb_t + 0.004  # depth 4 ms after colour
    gt_t = 99.9 + np.arange(30) * 0.03
    root = tmp_path / "rgbd_dataset_freiburg1_test"
    write_tum_folder(root, rgb_t, depth_t, gt_t)
    assert is_tum_rgbd(root)
    seq = read_tum_rgbd(root)
    assert len(seq) == 6 and seq.intrinsics == TUM_INTRINSICS["freiburg1"].scaled(640, 480)
    assert np.allclose(seq.timestamps, rgb_t)
    with pytest.raises(ValueError, match="is 64x48, the intrinsics say 640x480"):
        seq[0]
    seq = read_tum_rgbd(root, TUM_INTRINSICS["freiburg1"].scaled(W, H))
    f = seq[2]
    assert f.rgb.shape == (H, W, 3) and f.depth.dtype == np.float32
    assert np.allclose(f.depth, 2.0, atol=1e-3)  # depth_scale 5000
    assert f.pose is not None and f.pose[0, 3] == pytest.approx(rgb_t[2], abs=1e-9)
    assert seq.has_poses and f.timestamp == pytest.approx(rgb_t[2])


def test_frames_outside_ground_truth_have_no_pose(tmp_path):
    rgb_t = 10.0 + np.arange(5) * 0.1
    write_tum_folder(tmp_path / "t", rgb_t, rgb_t, gt_t=10.15 + np.arange(10) * 0.02)
    seq = read_tum_rgbd(tmp_path / "t", TUM_INTRINSICS["default"].scaled(W, H))
    have = [seq[i].pose is not None for i in range(len(seq))]
    assert have == [False, False, True, True, False]  # ground truth covers 10.15 .. 10.33
    assert not seq.has_poses


def test_unmatched_timestamps_are_errors(tmp_path):
    rgb_t = 50.0 + np.arange(4) * 0.1
    write_tum_folder(tmp_path / "far", rgb_t, rgb_t + 5.0)
    with pytest.raises(ValueError, match=r"rgb.txt and .*depth.txt: no colour/depth pair within 0.02 s"):
        read_tum_rgbd(tmp_path / "far")
    depth_t = rgb_t.copy()
    depth_t[1] += 0.5  # one colour frame without depth partner
    write_tum_folder(tmp_path / "some", rgb_t, depth_t)
    with pytest.raises(ValueError, match=r"rgb.txt: 1 of 4 colour frames have no depth image"):
        read_tum_rgbd(tmp_path / "some")
    with pytest.warns(UserWarning, match="they are skipped"):
        seq = read_tum_rgbd(tmp_path / "some", max_unmatched=0.5)
    assert len(seq) == 3


def test_depth_in_the_wrong_unit_is_detected(tmp_path):
    t = np.arange(3) * 0.1
    write_tum_folder(tmp_path / "mm", t, t, depth_m=2.0, depth_scale=5.0)  # saved in the wrong unit
    seq = read_tum_rgbd(tmp_path / "mm", TUM_INTRINSICS["default"].scaled(W, H))
    with pytest.raises(ValueError, match=r"depth/0.000000.png .*median depth is 0.002 m.*wrong unit"):
        seq[0]


def test_bad_list_lines_name_file_and_line(tmp_path):
    t = np.arange(3) * 0.1
    write_tum_folder(tmp_path / "x", t, t)
    (tmp_path / "x" / "rgb.txt").write_text("0.0 rgb/a.png\nabc rgb/b.png\n")
    with pytest.raises(ValueError, match=r"rgb.txt:2: timestamp 'abc' is not a number"):
        read_tum_rgbd(tmp_path / "x")
    with pytest.raises(ValueError, match="not a TUM RGB-D folder"):
        read_tum_rgbd(tmp_path)


def test_associate_is_one_to_one_closest_first():
    a = np.array([0.0, 0.010, 0.030])
    b = np.array([0.012, 0.031, 0.5])
    assert associate(a, b, 0.02).tolist() == [[1, 0], [2, 1]]  # 0.0 loses 0.012 to 0.010


def test_interpolate_poses_slerps_between_samples():
    P = np.stack([look_at([0, 0, 0], [1, 0, 0]), look_at([2, 0, 0], [2, 1, 0])])
    assert np.isnan(interpolate_poses(np.array([0.5]), np.array([0.0, 1.0]), P)).all()  # gap > 0.1 s
    out = interpolate_poses(np.array([0.5, 2.0]), np.array([0.0, 1.0]), P, max_gap=1.5)
    assert np.allclose(out[0, :3, 3], [1, 0, 0])
    R = out[0, :3, :3]
    assert np.allclose(R.T @ R, np.eye(3), atol=1e-9)
    assert np.isnan(out[1]).all()
