"""Frames written as a ROS bag (ROS 1 ``.bag``, ROS 2 sqlite3 or MCAP) with a RealSense driver's topics.

:func:`write_rosbag` is what the tests and the examples make their bags with (read back by
:class:`semmatch.io.bags.RosBagSequence`, which re-exports it); the messages come from
:mod:`semmatch.io.ros_images` and :mod:`semmatch.io.ros_transforms`, serialized by rosbags.
"""

from __future__ import annotations

import itertools
import os
import shutil
from collections.abc import Iterable, Sequence
from pathlib import Path

import numpy as np

from .geometry import Intrinsics
from .ros_images import camera_info_message, colour_message, depth_message
from .ros_transforms import LINK_TO_OPTICAL, TF_TYPES, pose_message, transform_message
from .sequences import Frame

__all__ = ["OPTICAL_FRAME", "write_rosbag"]

PathLike = str | os.PathLike

#: the camera's optical frame in the bags :func:`write_rosbag` writes
OPTICAL_FRAME = "camera_color_optical_frame"


def _ros_types(version: int):
    """The typestore to write with: ROS 1 Noetic (+ tf2_msgs/TFMessage) or ROS 2 Humble."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    if version == 2:
        return get_typestore(Stores.ROS2_HUMBLE)
    store = get_typestore(Stores.ROS1_NOETIC)
    store.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", TF_TYPES[0]))
    return store


class _BagWriter:
    """A ROS 1 or ROS 2 bag being written: connections by topic, messages serialized for the version."""

    def __init__(self, path: Path, version: int, storage: str) -> None:
        from rosbags.rosbag1 import Writer as Writer1
        from rosbags.rosbag2 import StoragePlugin
        from rosbags.rosbag2 import Writer as Writer2

        self.version, self.store = version, _ros_types(version)
        if version == 1:
            self.writer = Writer1(path)
        else:
            plugin = {"sqlite3": StoragePlugin.SQLITE3, "mcap": StoragePlugin.MCAP}[storage]
            self.writer = Writer2(path, version=9, storage_plugin=plugin)
        self.writer.open()
        self.connections: dict[str, object] = {}
        self.T = self.store.types

    def header(self, stamp_ns: int, frame: str):
        Time, Header = self.T["builtin_interfaces/msg/Time"], self.T["std_msgs/msg/Header"]
        t = Time(sec=stamp_ns // 1_000_000_000, nanosec=stamp_ns % 1_000_000_000)
        return Header(seq=0, stamp=t, frame_id=frame) if self.version == 1 else Header(stamp=t, frame_id=frame)

    def write(self, topic: str, msg, time_ns: int) -> None:
        typ = msg.__msgtype__
        if topic not in self.connections:
            self.connections[topic] = self.writer.add_connection(topic, typ, typestore=self.store)
        data = self.store.serialize_ros1(msg, typ) if self.version == 1 else self.store.serialize_cdr(msg, typ)
        self.writer.write(self.connections[topic], time_ns, data)

    def close(self) -> None:
        self.writer.close()


def write_rosbag(
    path: PathLike,
    frames: Iterable[Frame],
    intrinsics: Intrinsics | None = None,
    *,
    version: int = 2,
    storage: str = "sqlite3",
    compressed: bool | str = False,
    depth_encoding: str = "16UC1",
    poses: str | None = "odom",
    timestamps: Sequence[float] | None = None,
    depth_offset: float = 0.0,
) -> Path:
    """Write frames as a ROS bag with the topics of a RealSense camera driver (small bags for tests and examples).

    Topics: ``/camera/color/image_raw`` (``rgb8``; or ``.../compressed``),
    ``/camera/color/camera_info``, ``/camera/aligned_depth_to_color/image_raw`` (or
    ``.../compressedDepth``), in frame ``camera_color_optical_frame``; and the poses (each
    frame's ``T_world_camera``; frames without one are left out):

    - ``"odom"``: ``/odom`` (``nav_msgs/Odometry`` of ``base_link`` in ``odom``) and ``/tf_static``
      ``base_link -> camera_link -> camera_color_optical_frame`` (a camera 0.2 m ahead of and
      0.3 m above the base);
    - ``"tf"``: the same chain with ``odom -> base_link`` on ``/tf`` (read with
      ``pose_frames="odom:camera_color_optical_frame"``);
    - ``"pose"``: ``/camera/pose`` (``geometry_msgs/PoseStamped`` of the optical frame in ``map``);
    - None: no poses.

    Each message's receive time is its header stamp plus 1 ms (colour), 2 ms (depth).

    Parameters
    ----------
    path : path
        A new ``.bag`` file (``version=1``) or a new ROS 2 bag folder (``version=2``).
    frames : iterable of Frame
        RGB (uint8), depth (metres) and poses.
    intrinsics : Intrinsics, optional
        The camera; default: the first frame's.
    version : {1, 2}
    storage : {"sqlite3", "mcap"}
        ROS 2 storage (the folder then holds one ``.db3`` or ``.mcap`` file).
    compressed : bool or {"jpeg", "png"}
        Compressed colour (``True`` = JPEG) and image_transport ``compressedDepth`` depth.
    depth_encoding : {"16UC1", "32FC1"}
        Millimetres (``depth_to_uint16``) or float metres (NaN where no depth).
    timestamps : sequence of float, optional
        Header stamps (seconds, increasing, >= 0); default: the frames' timestamps.
    depth_offset : float
        Seconds added to the depth header stamps (an unsynchronised depth camera).

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    ValueError
        An unknown option, ``path`` exists, or stamps that are negative or not increasing.
    """
    path = Path(path)
    if version not in (1, 2) or storage not in ("sqlite3", "mcap") or depth_encoding not in ("16UC1", "32FC1") \
            or poses not in (None, "odom", "tf", "pose"):
        raise ValueError(f"write_rosbag: version {version!r} (1, 2), storage {storage!r} (sqlite3, mcap), "
                         f"depth_encoding {depth_encoding!r} (16UC1, 32FC1), poses {poses!r} (odom, tf, pose, None)")
    compressed = "jpeg" if compressed is True else (compressed or None)
    if compressed not in (None, "jpeg", "png"):
        raise ValueError(f"write_rosbag: compressed must be False, True, 'jpeg' or 'png', got {compressed!r}")
    if path.exists():
        raise ValueError(f"{path}: exists; write_rosbag writes a new bag only")
    frames = iter(frames)
    first = next(frames, None)
    if first is None:
        raise ValueError(f"{path}: no frames to write")
    from .outputs import sweep_stale, temp_dir

    sweep_stale(path)
    tmp = temp_dir(path)  # written whole beside the target, then renamed: no half-written bag
    try:
        w = _BagWriter(tmp / path.name, version, storage)
        try:
            n = _write_frames(w, path, itertools.chain([first], frames), intrinsics or first.intrinsics, timestamps,
                              depth_offset, compressed, depth_encoding, poses)
        finally:
            w.close()
        if timestamps is not None and len(timestamps) != n:
            raise ValueError(f"{path}: {len(timestamps)} stamps for {n} frames")
        os.replace(tmp / path.name, path)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return path


def _write_frames(w: _BagWriter, path: Path, frames: Iterable[Frame], intrinsics: Intrinsics,
                  timestamps: Sequence[float] | None, depth_offset: float, compressed: str | None,
                  depth_encoding: str, poses: str | None) -> int:
    """The messages of :func:`write_rosbag`, a frame at a time; returns the number of frames."""
    base_camera = np.eye(4)
    base_camera[:3, 3] = (0.2, 0.0, 0.3)
    colour_topic = "/camera/color/image_raw" + ("/compressed" if compressed else "")
    depth_topic = "/camera/aligned_depth_to_color/image_raw" + ("/compressedDepth" if compressed else "")
    previous = -np.inf
    k = -1
    for k, f in enumerate(frames):
        if timestamps is not None and k >= len(timestamps):
            raise ValueError(f"{path}: {len(timestamps)} stamps for more frames")
        t = float(f.timestamp if timestamps is None else timestamps[k])
        if not (t > previous and t >= 0 and t + depth_offset >= 0):
            raise ValueError(f"{path}: frame {k} has stamp {t} (depth {t + depth_offset}); stamps must be >= 0 and "
                             f"increasing (the one before: {previous}), one per frame")
        previous = t
        s, ds = round(t * 1e9), round((t + depth_offset) * 1e9)
        if k == 0 and poses in ("odom", "tf"):
            w.write("/tf_static", w.T[TF_TYPES[0]]([
                transform_message(w.T, w.header(s, "base_link"), "camera_link", base_camera),
                transform_message(w.T, w.header(s, "camera_link"), OPTICAL_FRAME, LINK_TO_OPTICAL)]), s)
        w.write("/camera/color/camera_info", camera_info_message(w.T, w.header(s, OPTICAL_FRAME), intrinsics), s)
        w.write(colour_topic, colour_message(w.T, w.header(s, OPTICAL_FRAME), f.rgb, compressed), s + 1_000_000)
        w.write(depth_topic, depth_message(w.T, w.header(ds, OPTICAL_FRAME), f.depth, depth_encoding,
                                           bool(compressed)), ds + 2_000_000)
        if f.pose is None or poses is None or not np.isfinite(f.pose).all():
            continue
        T_base = f.pose @ np.linalg.inv(base_camera @ LINK_TO_OPTICAL)  # T_odom_base
        if poses == "odom":
            cov = w.T["geometry_msgs/msg/PoseWithCovariance"](pose_message(w.T, T_base), np.zeros(36))
            V3 = w.T["geometry_msgs/msg/Vector3"]
            twist = w.T["geometry_msgs/msg/TwistWithCovariance"](
                w.T["geometry_msgs/msg/Twist"](V3(0.0, 0.0, 0.0), V3(0.0, 0.0, 0.0)), np.zeros(36))
            w.write("/odom", w.T["nav_msgs/msg/Odometry"](w.header(s, "odom"), "base_link", cov, twist), s)
        elif poses == "tf":
            w.write("/tf", w.T[TF_TYPES[0]]([transform_message(w.T, w.header(s, "odom"), "base_link", T_base)]), s)
        else:
            w.write("/camera/pose", w.T["geometry_msgs/msg/PoseStamped"](w.header(s, "map"), pose_message(w.T, f.pose)),
                    s)
    return k + 1
