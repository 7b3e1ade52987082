"""semmatch.io.bags: ROS 1 / ROS 2 (sqlite3, MCAP) bags written with rosbags itself, read back as frames."""

from __future__ import annotations

import dataclasses
import os
import pickle
import warnings
from concurrent.futures import ThreadPoolExecutor

import cv2
import numpy as np
import pytest

from semmatch.io import Frame, write_labels_folder
from semmatch.io.bag_writer import _BagWriter
from semmatch.io.bags import OPTICAL_FRAME, RosBagSequence, is_rosbag, write_rosbag
from semmatch.io.geometry import DEFAULT_INTRINSICS, look_at
from semmatch.io.ros_images import (
    IMAGE,
    QUANT_A,
    camera_info_intrinsics,
    colour_message,
    decode_colour,
    decode_depth,
    depth_message,
)
from semmatch.io.ros_transforms import transform_message

INTR = DEFAULT_INTRINSICS.scaled(40, 30)
STAMPS = 1700000000.0 + np.arange(6) / 30  # header stamps (s), 30 Hz


def synthetic_frames(n: int = 6, seed: int = 0) -> list[Frame]:
    """Smooth colour ramps (a different one per channel and frame, so that a swap of channels shows),
    a depth ramp (1-4 m) with a hole, camera poses walking along x."""
    h, w = INTR.shape
    y, x = np.mgrid[0:h, 0:w]
    frames = []
    for i in range(n):
        rgb = np.stack([x * 6 + 10 * i, y * 8 + 5 * seed, 255 - x * 3 - y * 2], axis=2) % 256
        depth = np.linspace(1.0, 4.0, h * w, dtype=np.float32).reshape(h, w) + np.float32(0.1 * i)
        depth[5:9, 10:20] = 0.0  # no measurement
        pose = look_at([0.3 * i, 0.0, 1.2], [0.3 * i + 0.5, 3.0, 0.8])
        frames.append(Frame(rgb.astype(np.uint8), depth, None, pose, INTR, index=i))
    return frames


def depth_tolerance(depth: np.ndarray, encoding: str, compressed: bool) -> np.ndarray:
    """How far a depth may move in the bag: half a millimetre (16UC1), none (raw 32FC1), or half a
    step of image_transport's inverse-depth quantisation (compressed 32FC1: d^2 / (2 A))."""
    if encoding == "16UC1":
        return np.full(depth.shape, 5e-4 + 1e-6)
    if not compressed:
        return np.zeros(depth.shape)
    return depth.astype(np.float64) ** 2 / (2 * QUANT_A) * 1.01 + 1e-6


CASES = [  # version, storage, compressed, depth encoding, poses
    (2, "sqlite3", False, "16UC1", "odom"),
    (2, "mcap", "jpeg", "32FC1", "tf"),
    (2, "mcap", "png", "16UC1", "pose"),
    (1, "sqlite3", "png", "32FC1", "odom"),
    (1, "sqlite3", False, "32FC1", "tf"),
]


def _name(case) -> str:
    return "ros{}-{}-{}-{}-{}".format(*case)


@pytest.mark.parametrize("case", CASES, ids=_name)
def test_round_trip(tmp_path, case):
    version, storage, compressed, encoding, poses = case
    frames = synthetic_frames()
    path = tmp_path / (_name(case) + (".bag" if version == 1 else ""))
    write_rosbag(path, frames, version=version, storage=storage, compressed=compressed, depth_encoding=encoding,
                 poses=poses, timestamps=STAMPS, depth_offset=0.004)
    assert is_rosbag(path)
    pose_args = {"odom": dict(pose_topic="/odom"), "pose": dict(pose_topic="/camera/pose"),
                 "tf": dict(pose_frames=f"odom:{OPTICAL_FRAME}")}[poses]
    with RosBagSequence(path, **pose_args) as seq:
        assert len(seq) == len(frames) and seq.intrinsics == INTR and seq.has_poses
        assert np.array_equal(seq.timestamps, np.round(STAMPS * 1e9) * 1e-9)
        assert np.allclose(seq.depth_timestamps, STAMPS + 0.004, atol=1e-9)
        assert seq.camera_frame == OPTICAL_FRAME
        assert seq.topics["color"].endswith("/compressed" if compressed else "image_raw")
        for f, g in zip(seq, frames):
            assert f.rgb.dtype == np.uint8 and f.depth.dtype == np.float32
            if compressed == "jpeg":  # lossy: close on average
                assert np.abs(f.rgb.astype(int) - g.rgb).mean() < 4
            else:
                assert np.array_equal(f.rgb, g.rgb)
            assert np.array_equal(f.depth > 0, g.depth > 0)
            assert (np.abs(f.depth - g.depth) <= depth_tolerance(g.depth, encoding, bool(compressed))).all()
            assert np.allclose(f.pose, g.pose, atol=1e-9)
            assert f.timestamp == seq.timestamps[f.index]


def test_a_bare_mcap_file_and_frames_slice_and_labels(tmp_path):
    frames = synthetic_frames()
    write_rosbag(tmp_path / "b", frames, storage="mcap", poses=None, timestamps=STAMPS)
    mcap = next((tmp_path / "b").glob("*.mcap"))
    assert is_rosbag(mcap) and is_rosbag(tmp_path / "b")
    labels = [np.full(INTR.shape, k, np.uint8) for k in range(3)]
    write_labels_folder(tmp_path / "labels", labels)
    seq = RosBagSequence(mcap, frames=slice(2, 5), labels=tmp_path / "labels")
    assert len(seq) == 3 and seq.poses is None and not seq.has_poses
    assert np.allclose(seq.timestamps, STAMPS[2:5])
    f = seq[-1]
    assert f.index == 2 and f.pose is None and np.array_equal(f.rgb, frames[4].rgb)
    assert (f.labels == 2).all()
    with pytest.raises(ValueError, match="no frames in slice"):
        RosBagSequence(mcap, frames=slice(10, 12))


def test_simulated_frames_round_trip(tmp_path):
    """Frames rendered by the simulator (tests/scenes.py) through a ROS 2 bag, poses via /tf's chain."""
    from scenes import furnished_room, orbit_poses

    from semmatch.sim import render_frames

    scene = furnished_room(0)
    intr = DEFAULT_INTRINSICS.scaled(80, 60)
    frames = render_frames(scene, orbit_poses(scene, 4, 1.2, 3), intr)
    write_rosbag(tmp_path / "sim", frames, poses="tf", timestamps=10.0 + np.arange(4) * 0.1)
    seq = RosBagSequence(tmp_path / "sim", pose_frames="odom")  # the camera: the images' frame
    assert seq.intrinsics == intr and seq.topics["pose"] == f"/tf odom -> {OPTICAL_FRAME}"
    for f, g in zip(seq, frames):
        assert np.array_equal(f.rgb, g.rgb) and np.allclose(f.pose, g.pose, atol=1e-9)
        assert np.abs(f.depth - g.depth).max() <= 5e-4 + 1e-6


def test_tf_chain_runs_both_ways_and_odometry_needs_the_camera_transform(tmp_path):
    frames = synthetic_frames(3)
    write_rosbag(tmp_path / "tf", frames, poses="tf", timestamps=STAMPS[:3])
    inverse = RosBagSequence(tmp_path / "tf", pose_frames=f"{OPTICAL_FRAME}:odom").poses
    assert np.allclose(inverse, np.linalg.inv([f.pose for f in frames]), atol=1e-9)
    with pytest.raises(ValueError, match="connect no chain from 'map' to .*; their frames: base_link, "):
        RosBagSequence(tmp_path / "tf", pose_frames="map")
    with pytest.raises(ValueError, match="not both"):
        RosBagSequence(tmp_path / "tf", pose_frames="odom", pose_topic="/odom")
    with pytest.raises(ValueError, match="give 'odom' no parent frame"):
        RosBagSequence(tmp_path / "tf", pose_topic="/tf", pose_frames=":odom")
    from_root = RosBagSequence(tmp_path / "tf", pose_topic="/tf").poses  # odom, the tree's root, to the camera
    assert np.allclose(from_root, [f.pose for f in frames], atol=1e-9)
    # odometry of base_link without /tf_static: the camera's pose is unknown, said so
    w = _BagWriter(tmp_path / "odom_only", 2, "sqlite3")
    ns = (STAMPS[:3] * 1e9).astype(np.int64)
    for f, s in zip(frames, ns):
        header = w.header(int(s), OPTICAL_FRAME)
        w.write("/camera/color/image_raw", colour_message(w.T, header, f.rgb), int(s))
        w.write("/camera/depth/image_raw", depth_message(w.T, header, f.depth), int(s))
        w.write("/base_pose", transform_message(w.T, w.header(int(s), "odom"), "base_link", f.pose), int(s))
    w.close()
    with pytest.raises(ValueError, match="poses are of frame 'base_link'.*pass --pose-frames WORLD:camera_color"):
        RosBagSequence(tmp_path / "odom_only", pose_topic="/base_pose", intrinsics=INTR)
    # with no camera_info topic the error lists the topics and names the flag; given intrinsics do without
    with pytest.raises(ValueError, match=r"no camera info topic .*--camera-info-topic TOPIC; the bag's topics:\n"
                                         r"  /base_pose +geometry_msgs/msg/TransformStamped  \(3 messages\)"):
        RosBagSequence(tmp_path / "odom_only")
    assert len(RosBagSequence(tmp_path / "odom_only", intrinsics=INTR)) == 3


def test_topic_choice_errors_list_the_topics(tmp_path):
    frames = synthetic_frames(2)
    w = _BagWriter(tmp_path / "two_cameras", 2, "mcap")
    for f, s in zip(frames, (STAMPS[:2] * 1e9).astype(np.int64)):
        header = w.header(int(s), OPTICAL_FRAME)
        for cam in ("front", "rear"):
            w.write(f"/{cam}/color/image_raw", colour_message(w.T, header, f.rgb), int(s))
        w.write("/rear/depth/image_raw", depth_message(w.T, header, f.depth), int(s))
    w.close()
    path = tmp_path / "two_cameras"
    with pytest.raises(ValueError, match=r"2 colour topics \(.*\): /front/color/image_raw, /rear/color/image_raw; "
                                         r"pass --color-topic TOPIC to choose one; the bag's topics:\n"
                                         r"  /front/color/image_raw +sensor_msgs/msg/Image  \(2 messages\)"):
        RosBagSequence(path, intrinsics=INTR)
    seq = RosBagSequence(path, color_topic="/rear/color/image_raw", intrinsics=INTR)
    assert seq.topics["depth"] == "/rear/depth/image_raw" and len(seq) == 2
    with pytest.raises(ValueError, match=r"no topic /nope \(--depth-topic\); the bag's topics:"):
        RosBagSequence(path, color_topic="/rear/color/image_raw", depth_topic="/nope", intrinsics=INTR)
    with pytest.raises(ValueError, match=r"topic /rear/color/image_raw \(--pose-topic\) is sensor_msgs/msg/Image, "
                                         r"expected nav_msgs/msg/Odometry or"):
        RosBagSequence(path, color_topic="/rear/color/image_raw", pose_topic="/rear/color/image_raw",
                       intrinsics=INTR)
    with pytest.raises(ValueError, match="depth encoding 'rgb8' is not read; expected 16UC1"):
        RosBagSequence(path, color_topic="/rear/color/image_raw", depth_topic="/front/color/image_raw",
                       intrinsics=INTR)


def test_unpaired_stamps_and_wrong_depth_units_are_refused(tmp_path):
    frames = synthetic_frames(4)
    write_rosbag(tmp_path / "late", frames, timestamps=100.0 + np.arange(4), depth_offset=0.3)  # 1 Hz
    with pytest.raises(ValueError, match=r"colour topic .* and depth topic .*: no colour/depth pair within 0.02 s"):
        RosBagSequence(tmp_path / "late")
    assert len(RosBagSequence(tmp_path / "late", max_difference=0.31)) == 4
    mm = [dataclasses.replace(f, depth=f.depth * 1000) for f in frames]  # millimetres written as 32FC1 metres
    write_rosbag(tmp_path / "mm", mm, depth_encoding="32FC1", timestamps=STAMPS[:4])
    with pytest.raises(ValueError, match=r"aligned_depth_to_color/image_raw at .*: median depth is .* m, outside"):
        RosBagSequence(tmp_path / "mm")
    seq = RosBagSequence(tmp_path / "mm", check_units=False)
    assert seq[0].depth.max() > 1000


def test_not_a_bag(tmp_path):
    (tmp_path / "x.txt").write_text("hello")
    (tmp_path / "fake.bag").write_text("not a bag")
    assert not is_rosbag(tmp_path) and not is_rosbag(tmp_path / "x.txt") and not is_rosbag(tmp_path / "none")
    with pytest.raises(FileNotFoundError, match="no such ROS bag"):
        RosBagSequence(tmp_path / "none.bag")
    with pytest.raises(ValueError, match="not a ROS bag"):
        RosBagSequence(tmp_path)
    with pytest.raises(ValueError, match="fake.bag: not a readable ROS bag"):
        RosBagSequence(tmp_path / "fake.bag")
    with pytest.raises(ValueError, match="exists"):
        write_rosbag(tmp_path / "x.txt", synthetic_frames(1))
    with pytest.raises(ValueError, match="frame 1 has stamp 0.0 .* must be >= 0 and increasing"):
        write_rosbag(tmp_path / "same_stamps", synthetic_frames(2))  # Frame's default timestamp: 0 for both
    with pytest.raises(ValueError, match="2 stamps for more frames"):
        write_rosbag(tmp_path / "short.bag", synthetic_frames(3), version=1, timestamps=[1.0, 2.0])
    with pytest.raises(ValueError, match="4 stamps for 3 frames"):
        write_rosbag(tmp_path / "long", synthetic_frames(3), timestamps=[1.0, 2.0, 3.0, 4.0])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fake.bag", "x.txt"]  # nothing half-written left


def test_threads_and_pickling_read_the_same_frames(tmp_path):
    frames = synthetic_frames()
    write_rosbag(tmp_path / "b", frames, timestamps=STAMPS, poses="odom")
    seq = RosBagSequence(tmp_path / "b", pose_topic="/odom")
    with ThreadPoolExecutor(2) as ex:
        got = list(ex.map(seq.__getitem__, range(len(seq))))
    again = pickle.loads(pickle.dumps(seq))
    for f, g, h in zip(got, frames, again):
        assert np.array_equal(f.rgb, g.rgb) and np.array_equal(h.depth, f.depth)
        assert np.allclose(h.pose, g.pose)
    seq.close()
    again.close()


def test_raw_encodings_row_padding_and_distortion():
    from rosbags.typesys import Stores, get_typestore

    T = get_typestore(Stores.ROS2_HUMBLE).types
    Image, Header, Time = T[IMAGE], T["std_msgs/msg/Header"], T["builtin_interfaces/msg/Time"]
    rgb = np.random.default_rng(1).integers(0, 256, (3, 4, 3), dtype=np.uint8)

    def image(encoding: str, pixels: np.ndarray, pad: int = 2):
        rows = pixels.reshape(3, -1)
        data = np.concatenate([rows, np.zeros((3, pad), np.uint8)], axis=1)  # step > width * channels
        return Image(Header(Time(1, 0), "cam"), 3, 4, encoding, 0, data.shape[1], data.ravel())

    assert np.array_equal(decode_colour(image("rgb8", rgb)), rgb)
    assert np.array_equal(decode_colour(image("bgr8", rgb[..., ::-1].copy())), rgb)
    rgba = np.concatenate([rgb, np.full((3, 4, 1), 7, np.uint8)], axis=2)
    assert np.array_equal(decode_colour(image("bgra8", rgba[..., [2, 1, 0, 3]].copy())), rgb)
    assert np.array_equal(decode_colour(image("mono8", rgb[..., 0].copy())), np.repeat(rgb[..., :1], 3, axis=2))
    with pytest.raises(ValueError, match="frame 7: colour encoding 'yuv422' is not read"):
        decode_colour(image("yuv422", rgb[..., :2].copy()), "frame 7")
    Compressed = T["sensor_msgs/msg/CompressedImage"]
    mm = np.array([[0, 1000, 65535], [2500, 400, 7]], np.uint16)
    png = cv2.imencode(".png", mm)[1].ravel()
    depth = decode_depth(Compressed(Header(Time(1, 0), "cam"), "16UC1; png compressed ", png), "d")
    assert np.array_equal(depth, np.where(mm == 65535, 0, mm / np.float32(1000)).astype(np.float32))
    jpeg = cv2.imencode(".jpg", rgb)[1].ravel()
    with pytest.raises(ValueError, match="must hold 16-bit single-channel PNGs .* decodes to uint8"):
        decode_depth(Compressed(Header(Time(1, 0), "cam"), "rgb8; jpeg compressed bgr8", jpeg), "d")
    with pytest.raises(ValueError, match="needs 12 bytes a row"):
        decode_colour(Image(Header(Time(1, 0), "cam"), 3, 4, "rgb8", 0, 10, np.zeros(30, np.uint8)))
    info = T["sensor_msgs/msg/CameraInfo"](
        Header(Time(1, 0), "cam"), 30, 40, "plumb_bob", np.array([0.1, 0, 0, 0, 0]),
        np.array([50.0, 0, 20, 0, 51, 15, 0, 0, 1]), np.eye(3).ravel(), np.zeros(12), 0, 0,
        T["sensor_msgs/msg/RegionOfInterest"](0, 0, 0, 0, False))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        intr = camera_info_intrinsics(info, "info")
    assert (intr.width, intr.height, intr.fx, intr.fy, intr.cx, intr.cy) == (40, 30, 50, 51, 20, 15)
    assert any("distortion plumb_bob [0.1" in str(c.message) for c in caught)


def test_tf_poses_are_interpolated_between_samples_and_gaps_stay_unknown(tmp_path):
    """/tf at 20 Hz, off the camera's stamps: the camera's pose is interpolated along the moving edge and
    composed with the static one; a frame in a gap longer than max_pose_gap has no pose."""
    from semmatch.io.ros_transforms import TF_TYPES

    frames = synthetic_frames(3)
    stamps = np.array([10.0, 10.13, 10.5])
    w = _BagWriter(tmp_path / "tf20", 2, "sqlite3")
    base_camera = np.eye(4)
    base_camera[:3, :3] = [[0, 0, 1], [-1, 0, 0], [0, -1, 0]]  # base_link -> optical frame
    base_camera[:3, 3] = (0.1, 0.0, 0.5)
    s0 = int(stamps[0] * 1e9)
    w.write("/tf_static", w.T[TF_TYPES[0]]([transform_message(w.T, w.header(s0, "base_link"), OPTICAL_FRAME,
                                                              base_camera)]), s0)
    for f, t in zip(frames, stamps):
        s = round(t * 1e9)
        header = w.header(s, OPTICAL_FRAME)
        w.write("/camera/color/image_raw", colour_message(w.T, header, f.rgb), s)
        w.write("/camera/depth/image_raw", depth_message(w.T, header, f.depth), s)
    for t in np.r_[np.arange(9.95, 10.2, 0.05), 10.6]:  # no sample between 10.2 and 10.6
        odom_base = np.eye(4)
        odom_base[0, 3] = 2.0 * (t - 10.0)  # driving along x at 2 m/s
        s = round(t * 1e9)
        w.write("/tf", w.T[TF_TYPES[0]]([transform_message(w.T, w.header(s, "odom"), "base_link", odom_base)]), s)
    w.close()
    seq = RosBagSequence(tmp_path / "tf20", pose_topic="/tf", intrinsics=INTR)  # the root of the tree: odom
    assert seq.topics["pose"] == f"/tf odom -> {OPTICAL_FRAME}"
    assert np.isfinite(seq.poses[:2]).all() and np.isnan(seq.poses[2]).all() and not seq.has_poses
    for k in range(2):
        expected = np.eye(4)
        expected[0, 3] = 2.0 * (stamps[k] - 10.0)
        assert np.allclose(seq.poses[k], expected @ base_camera, atol=1e-9)
    assert seq[2].pose is None
    wide = RosBagSequence(tmp_path / "tf20", pose_frames="odom", intrinsics=INTR, max_pose_gap=0.5)
    assert wide.has_poses and wide.poses[2][0, 3] == pytest.approx(2.0 * 0.5 + 0.1)


def test_pose_messages_of_every_type():
    from rosbags.typesys import Stores, get_typestore

    from semmatch.io.ros_transforms import pose_message, pose_of

    T = get_typestore(Stores.ROS2_HUMBLE).types
    Header, Time = T["std_msgs/msg/Header"], T["builtin_interfaces/msg/Time"]
    pose = look_at([1.0, 2.0, 0.5], [3.0, 0.0, 0.2])
    h = Header(Time(5, 0), "/map")  # ROS 1's leading slash is dropped
    msg_pose = pose_message(T, pose)
    cov = T["geometry_msgs/msg/PoseWithCovariance"](msg_pose, np.zeros(36))
    for msg, child in [(T["geometry_msgs/msg/PoseStamped"](h, msg_pose), ""),
                       (T["geometry_msgs/msg/PoseWithCovarianceStamped"](h, cov), ""),
                       (transform_message(T, h, "/base_link", pose), "base_link")]:
        got, parent, got_child = pose_of(msg)
        assert np.allclose(got, pose, atol=1e-12) and parent == "map" and got_child == child


def test_sequence_to_rosbag_script(tmp_path, capsys):
    """scripts/sequence_to_rosbag.py: a sequence folder written as a ROS 1 bag reads back the same."""
    import importlib.util
    from pathlib import Path

    from semmatch.io import SequenceWriter, read_sequence

    spec = importlib.util.spec_from_file_location(
        "sequence_to_rosbag", Path(__file__).parents[1] / "scripts" / "sequence_to_rosbag.py")
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    frames = synthetic_frames(4)
    with SequenceWriter(tmp_path / "seq", INTR) as w:
        for f in frames:
            w.add(f.rgb, f.depth, f.pose)  # timestamps 0, 1, 2, 3
    assert script.main([str(tmp_path / "seq"), str(tmp_path / "robot.bag"), "--version", "1", "--poses", "tf",
                        "--frames", "3"]) == 0
    assert "robot.bag: 3 frames" in capsys.readouterr().out
    seq, ref = RosBagSequence(tmp_path / "robot.bag", pose_topic="/tf"), read_sequence(tmp_path / "seq")
    assert len(seq) == 3 and np.array_equal(seq.timestamps, [0.0, 1.0, 2.0])
    for f, g in zip(seq, ref):
        assert np.array_equal(f.rgb, g.rgb) and np.array_equal(f.depth, g.depth)
        assert np.allclose(f.pose, g.pose, atol=1e-6)  # poses.txt keeps 9 decimals
    assert script.main([str(tmp_path / "seq"), str(tmp_path / "robot.bag")]) == 2
    assert "exists" in capsys.readouterr().err


def test_depth_not_registered_to_the_colour_camera(tmp_path):
    """Depth of another size is refused at open; depth in another frame is warned about."""
    frames = synthetic_frames(2)
    w = _BagWriter(tmp_path / "unaligned", 2, "sqlite3")
    for f, s in zip(frames, (STAMPS[:2] * 1e9).astype(np.int64)):
        w.write("/camera/color/image_raw", colour_message(w.T, w.header(int(s), OPTICAL_FRAME), f.rgb), int(s))
        depth_header = w.header(int(s), "camera_depth_optical_frame")
        w.write("/camera/depth/image_rect_raw", depth_message(w.T, depth_header, f.depth[:-2]), int(s))
        w.write("/camera/depth_same_size", depth_message(w.T, depth_header, f.depth), int(s))
    w.close()
    with pytest.raises(ValueError, match=r"image_rect_raw at .*: depth images are 40x28, the colour images 40x30 .*"
                                         r"not registered to the colour camera"):
        RosBagSequence(tmp_path / "unaligned", depth_topic="/camera/depth/image_rect_raw", intrinsics=INTR)
    with pytest.warns(UserWarning, match="is in frame 'camera_depth_optical_frame', colour topic .* in "
                                         "'camera_color_optical_frame'"):
        seq = RosBagSequence(tmp_path / "unaligned", depth_topic="/camera/depth_same_size", intrinsics=INTR)
    assert len(seq) == 2


def test_frame_files_name_the_bag_and_the_pose_cache_keys_on_them(tmp_path, monkeypatch):
    """frame_files gives the bag's own files (a folder: metadata.yaml and storage), so the
    --estimate-poses cache keys a bag on its files, stamps and topics without decoding a frame."""
    from semmatch.poses.recording_poses import poses_cache_key

    frames = synthetic_frames()
    write_rosbag(tmp_path / "b", frames, poses=None, timestamps=STAMPS)
    seq = RosBagSequence(tmp_path / "b")
    files = seq.frame_files(3)
    assert {f.name for f in files} >= {"metadata.yaml"} and any(f.suffix == ".db3" for f in files)
    assert all(f.parent == tmp_path / "b" for f in files)
    with pytest.raises(IndexError):
        seq.frame_files(len(seq))
    write_rosbag(tmp_path / "m", frames, storage="mcap", poses=None, timestamps=STAMPS)
    mcap = next((tmp_path / "m").glob("*.mcap"))
    assert RosBagSequence(mcap).frame_files(0) == (mcap,)

    def no_decoding(self, i):
        raise AssertionError("the cache key decoded a frame")

    monkeypatch.setattr(RosBagSequence, "__getitem__", no_decoding)
    key = poses_cache_key(seq, {"residual": "hybrid"})
    assert key == poses_cache_key(RosBagSequence(tmp_path / "b"), {"residual": "hybrid"})
    assert key != poses_cache_key(RosBagSequence(tmp_path / "b", frames=slice(1, 4)), {"residual": "hybrid"})
    other = RosBagSequence(tmp_path / "b")
    other.topics = {**other.topics, "color": "/other/color/image_raw"}  # another topic of the same bag
    assert key != poses_cache_key(other, {"residual": "hybrid"})
    db3 = next((tmp_path / "b").glob("*.db3"))
    os.utime(db3, ns=(db3.stat().st_atime_ns, db3.stat().st_mtime_ns + 10**9))  # the bag rewritten
    assert key != poses_cache_key(RosBagSequence(tmp_path / "b"), {"residual": "hybrid"})
