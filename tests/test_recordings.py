"""semmatch.io.recordings: TUM RGB-D folders (association, ground truth, intrinsics, bad input)."""

from __future__ import annotations

import numpy as np
import pytest

from semmatch.io import write_depth, write_image, write_tum
from semmatch.io.geometry import Intrinsics, look_at
from semmatch.io.recordings import TUM_INTRINSICS, associate, interpolate_poses, is_tum_rgbd, read_tum_rgbd

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


# ----------------------------------------------------------------------------- 7-Scenes, plain folders, traps
def write_7scenes(root, n=3, *, depth_mm=2000, holes=0.0, camera=True, poses=True):
    """A tiny 7-Scenes folder: frame-XXXXXX.color.png / .depth.png (mm) / .pose.txt."""
    import cv2

    root.mkdir(parents=True, exist_ok=True)
    for i in range(n):
        write_image(root / f"frame-{i:06d}.color.png", np.full((H, W, 3), 40 * i, np.uint8))
        d = np.full((H, W), depth_mm, np.uint16)
        d.reshape(-1)[: int(holes * d.size)] = 65535  # 7-Scenes' "no measurement"
        cv2.imwrite(str(root / f"frame-{i:06d}.depth.png"), d)
        if poses:
            T = look_at([0.1 * i, 0.0, 1.0], [0.1 * i, 5.0, 1.0])
            np.savetxt(root / f"frame-{i:06d}.pose.txt", T if i != 1 else np.full((4, 4), -np.inf))
    if camera:
        np.savetxt(root / "camera-intrinsics.txt", [[50.0, 0, 32], [0, 50.0, 24], [0, 0, 1]])


def test_7scenes_folder_reads_frames_camera_and_poses(tmp_path):
    from semmatch.io.recordings import SevenScenesSequence, is_7scenes, read_recording

    write_7scenes(tmp_path / "kitchen", 4)
    assert is_7scenes(tmp_path / "kitchen") and not is_tum_rgbd(tmp_path / "kitchen")
    seq = read_recording(tmp_path / "kitchen")
    assert isinstance(seq, SevenScenesSequence) and len(seq) == 4
    assert (seq.intrinsics.fx, seq.intrinsics.cx, seq.intrinsics.shape, seq.intrinsics.depth_scale) == (
        50.0, 32.0, (H, W), 1000.0)
    f = seq[2]
    assert np.allclose(f.depth, 2.0) and f.rgb[0, 0, 0] == 80 and f.pose[0, 3] == pytest.approx(0.2)
    assert seq[1].pose is None and np.isnan(seq.poses[1]).all() and not seq.has_poses  # -inf pose: unknown
    assert len(SevenScenesSequence(tmp_path / "kitchen", frames=slice(1, 3))) == 2
    (tmp_path / "kitchen" / "frame-000003.pose.txt").write_text("1 0 0\n0 1 0\n")
    with pytest.raises(ValueError, match=r"frame-000003.pose.txt: expected a 4x4 pose \(4x4\), got shape \(2, 3\)"):
        read_recording(tmp_path / "kitchen")
    (tmp_path / "kitchen" / "frame-000002.color.png").unlink()
    with pytest.raises(ValueError, match=r"frame-000002.depth.png: no colour image frame-000002.color.png/.jpg"):
        SevenScenesSequence(tmp_path / "kitchen")


def test_7scenes_without_camera_file_warns_and_names_the_camera(tmp_path):
    from semmatch.io.recordings import SEVEN_SCENES_INTRINSICS, read_recording

    write_7scenes(tmp_path / "k", 2, camera=False)
    with pytest.warns(UserWarning, match=r"no intrinsics.json; ASSUMING the Microsoft 7-Scenes Kinect .*fx 585"):
        seq = read_recording(tmp_path / "k")
    assert seq.intrinsics == SEVEN_SCENES_INTRINSICS


def test_65535_depth_is_a_hole_not_a_wrong_unit(tmp_path):
    from semmatch.io.recordings import read_recording

    write_7scenes(tmp_path / "k", 2, holes=0.6)  # 60 % of the pixels are holes
    f = read_recording(tmp_path / "k")[0]
    assert (f.depth == 0).mean() == pytest.approx(0.6, abs=0.01)
    assert np.allclose(f.depth[f.depth > 0], 2.0)


def test_tum_without_intrinsics_warns_and_short_names_select_the_camera(tmp_path):
    from semmatch.io.recordings import tum_camera

    assert tum_camera("fr1_desk") == "freiburg1" and tum_camera("rgbd_dataset_freiburg3_long_office") == "freiburg3"
    assert tum_camera("FR2-xyz") == "freiburg2" and tum_camera("frame_12") is None and tum_camera("fr12") is None
    t = np.arange(3) * 0.1
    write_tum_folder(tmp_path / "fr2_xyz", t, t)
    with pytest.warns(UserWarning, match=r"fr2_xyz: no intrinsics.json; ASSUMING the TUM freiburg2 camera \(fx 520.9"):
        seq = read_tum_rgbd(tmp_path / "fr2_xyz")
    assert seq.intrinsics == TUM_INTRINSICS["freiburg2"]


def test_millimetre_depth_read_at_tum_scale_is_refused(tmp_path):
    t = np.arange(3) * 0.1
    # a millimetre recording (2.2 m away) in a TUM folder without intrinsics.json: read at 1/5000 m it is 0.44 m
    write_tum_folder(tmp_path / "fr1_mm", t, t, depth_m=2.2, depth_scale=1000.0)
    with pytest.warns(UserWarning, match="ASSUMING"), pytest.raises(
            ValueError, match=r"fr1_mm: at depth_scale 5000 the median depth .* is 0.44 m.*millimetres it is 2.20 m"
                              r".*\"depth_scale\": 1000.*5x too small"):
        read_tum_rgbd(tmp_path / "fr1_mm")
    (tmp_path / "fr1_mm" / "intrinsics.json").write_text(
        '{"width": 64, "height": 48, "fx": 50, "fy": 50, "cx": 32, "cy": 24, "depth_scale": 1000}')
    seq = read_tum_rgbd(tmp_path / "fr1_mm")  # the right scale: accepted, no warning
    assert np.allclose(seq[0].depth, 2.2)


def test_plain_folder_needs_its_camera(tmp_path):
    from semmatch.io import write_intrinsics
    from semmatch.io.recordings import PlainFolderSequence, read_recording

    root = tmp_path / "plain"
    for i in range(3):
        write_image(root / "color" / f"{i:04d}.jpg", np.full((H, W, 3), 100, np.uint8))
        write_depth(root / "depth" / f"{i:04d}.png", np.full((H, W), 1.5, np.float32))
    with pytest.raises(ValueError, match="plain: no intrinsics.json; a plain folder names no camera"):
        read_recording(root)
    write_intrinsics(root / "intrinsics.json", Intrinsics(W, H, 50, 50, 32, 24))
    seq = read_recording(root)
    assert isinstance(seq, PlainFolderSequence) and len(seq) == 3 and seq.poses is None
    assert np.allclose(seq[1].depth, 1.5) and seq[1].pose is None
    (root / "depth" / "0002.png").unlink()
    with pytest.raises(ValueError, match="3 colour and 2 depth images"):
        read_recording(root)
    with pytest.raises(ValueError, match="not a recording folder"):
        read_recording(tmp_path)


def test_cli_points_to_estimate_poses_and_prints_plain_warnings(tmp_path, capsys):
    from semmatch.cli import main

    write_7scenes(tmp_path / "k", 2, camera=False, poses=False)
    assert main(["reconstruct", str(tmp_path / "k"), "--out", str(tmp_path / "m.ply"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "semmatch reconstruct: warning: " in err and "ASSUMING the Microsoft 7-Scenes Kinect" in err
    assert "warnings.warn" not in err and "UserWarning" not in err  # no Python source lines
    assert "has no recorded poses; pass --estimate-poses" in err and "semmatch.poses.odometry" not in err


def test_cli_anchors_the_chain_where_the_ground_truth_starts(tmp_path, capsys):
    import json

    from semmatch.cli import main

    write_7scenes(tmp_path / "k", 5)
    for i in (0, 1):  # the motion capture starts at frame 2
        (tmp_path / "k" / f"frame-{i:06d}.pose.txt").unlink()
    assert main(["reconstruct", str(tmp_path / "k"), "--estimate-poses", "--out", str(tmp_path / "m.ply"),
                 "--voxel-size", "0.1", "--quiet", "--json"]) == 0
    out, err = capsys.readouterr()
    assert "warning: " in err and "the ground truth starts at frame 2, not 0" in err
    info = json.loads(out.strip().splitlines()[-1])
    assert info["gt_first_frame"] == 2 and info["n_frames"] == 3
