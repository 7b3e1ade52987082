"""ROS bags as sequences of :class:`semmatch.io.Frame`: ROS 1 ``.bag``, ROS 2 bag folders, MCAP files.

Read through the pure-Python `rosbags <https://ternaris.gitlab.io/rosbags/>`_ library (no ROS
install). :class:`RosBagSequence` is lazy and random access like the folder readers of
:mod:`semmatch.io.recordings` (``len(seq)``, ``seq[i] -> Frame``); :func:`is_rosbag` tells a bag
from other paths; :func:`write_rosbag` writes frames as a bag (the tests' and examples' bags).
The messages are decoded by :mod:`semmatch.io.ros_images` (images, camera info) and
:mod:`semmatch.io.ros_transforms` (poses, the TF tree).

What is read
------------
- Colour: ``sensor_msgs/msg/Image`` (``rgb8``, ``bgr8``, ``rgba8``, ``bgra8``, ``mono8``) or
  ``sensor_msgs/msg/CompressedImage`` (JPEG or PNG, as image_transport's ``compressed``).
- Depth: ``sensor_msgs/msg/Image`` ``16UC1`` (or ``mono16``; millimetres, REP 118) or ``32FC1``
  (metres), or ``sensor_msgs/msg/CompressedImage`` in image_transport's ``compressedDepth`` PNG
  format (a 12-byte header, then a 16-bit PNG: millimetres for ``16UC1``, quantised inverse
  depth for ``32FC1``), or a plain 16-bit PNG (millimetres). 0, NaN, inf and 65535 (16-bit) are
  "no measurement". The depth must be
  registered to the colour image (same size, same camera: e.g. RealSense's
  ``aligned_depth_to_color``, OpenNI's ``depth_registered``); it is not reprojected. Depth of
  another size is refused when the bag is opened; depth in another frame is warned about.
- Intrinsics: the first ``sensor_msgs/msg/CameraInfo`` of the colour camera (``K``, width,
  height). The images are taken as undistorted pinhole images: a non-zero distortion is
  warned about (use the rectified ``image_rect`` topics).
- Colour and depth are paired by their header stamps as TUM's ``associate.py`` pairs its
  timestamps (:func:`semmatch.io.timestamps.associate_frames`); the frame's timestamp is the
  colour header stamp (seconds).
- Poses (optional), ``T_world_camera`` of the camera's optical frame (x right, y down, z forward,
  REP 103's ``*_optical_frame``; the frame of the colour images' headers) in a z-up world in
  metres (REP 103's ``map`` and ``odom`` are), interpolated at the colour stamps (linear
  translation, slerp rotation; NaN where the samples around a frame are more than
  ``max_pose_gap`` apart):

  - ``pose_topic``: ``nav_msgs/msg/Odometry``, ``geometry_msgs/msg/PoseStamped``,
    ``PoseWithCovarianceStamped`` or ``TransformStamped``. Odometry and TransformStamped name
    the frame they pose (``child_frame_id``, e.g. ``base_link``); when that is not the
    colour images' frame, the transform from it to the camera is looked up in ``/tf_static``
    and ``/tf`` and composed (an error when the bag has none). A PoseStamped is taken as the
    pose of the camera's optical frame itself.
  - ``pose_frames="WORLD:CAMERA"`` (or ``"WORLD"``: the camera is the colour images' frame):
    the chain of transforms from WORLD to CAMERA through the TF tree of ``/tf`` and
    ``/tf_static`` (e.g. ``map -> odom -> base_link -> camera_link -> camera_color_optical_frame``).
    ``pose_topic="/tf"`` (a ``TFMessage`` topic) means the same, with WORLD the root of the
    camera's tree unless ``pose_frames`` names it.

Topic defaults: colour is the one Image/CompressedImage topic whose name does not contain
"depth", depth the one that does (of two, the one named ``aligned``/``registered``; of a raw
topic and its own ``/compressed`` or ``/compressedDepth``, the raw one), camera info the
CameraInfo topic nearest the colour topic's namespace. When none or several fit, the error lists
the bag's topics (name, type, message count) and names the flag to pass.

Random access without loading the bag: opening reads the colour and depth messages once to
index their header stamps (only the first 12 bytes of each are parsed; nothing is kept but the
stamps), and ``seq[i]`` reads the two messages of frame ``i`` from the storage by their
receive time. Each thread and process opens its own reader of the bag.
"""

from __future__ import annotations

import functools
import os
import struct
import threading
import warnings
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from .bag_writer import OPTICAL_FRAME, write_rosbag
from .geometry import Intrinsics
from .images import check_depth_units
from .readers.base import ImageSequence as _ImageSequence
from .ros_images import (
    CAMERA_INFO,
    COMPRESSED_IMAGE,
    IMAGE,
    camera_info_intrinsics,
    decode_colour,
    decode_depth,
)
from .ros_transforms import (
    POSE_TYPES,
    TF_TYPES,
    TfTree,
    pose_of,
    stamp_seconds,
    tf_frame,
)
from .sequences import frame_index
from .timestamps import associate_frames, interpolate_poses

__all__ = ["OPTICAL_FRAME", "is_rosbag", "RosBagSequence", "read_rosbag", "write_rosbag"]

PathLike = str | os.PathLike



# ----------------------------------------------------------------------------- opening
def is_rosbag(path: PathLike) -> bool:
    """True when ``path`` is a ROS 1 ``.bag`` file, an ``.mcap`` file, or a ROS 2 bag folder.

    A ROS 2 bag folder holds ``metadata.yaml`` and its storage files (``*.db3`` or ``*.mcap``, or
    those compressed as ``*.zstd``).
    """
    p = Path(path)
    if p.is_file():
        return p.suffix.lower() in (".bag", ".mcap")
    return p.is_dir() and (p / "metadata.yaml").is_file() and any(
        f.name.endswith((".db3", ".mcap", ".db3.zstd", ".mcap.zstd")) for f in p.iterdir())


@functools.cache
def _default_types():
    """ROS 2 Humble's message types: for ROS 2 bags that carry no definitions (sqlite3 before Iron)."""
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_HUMBLE)


def _open_reader(path: Path):
    """An open :class:`rosbags.highlevel.AnyReader` of ``path`` (types from the bag, else ROS 2 Humble's)."""
    from rosbags.highlevel import AnyReader, AnyReaderError

    reader = AnyReader([path], default_typestore=_default_types())
    try:
        reader.open()
    except AnyReaderError as e:
        raise ValueError(f"{path}: not a readable ROS bag ({e})") from None
    return reader


def _stamp_ns(raw: bytes | memoryview, cdr: bool) -> int:
    """The header stamp (ns) of a serialized message that starts with a ``std_msgs/Header``.

    ROS 1: ``uint32 seq, uint32 sec, uint32 nsec``; CDR (ROS 2): a 4-byte encapsulation header
    whose second byte's low bit says little endian, then ``int32 sec, uint32 nanosec``. Either
    way the stamp is bytes 4 to 12.
    """
    fmt = "<iI" if not cdr or raw[1] & 1 else ">iI"
    sec, nsec = struct.unpack_from(fmt, raw, 4)
    return sec * 1_000_000_000 + nsec


# ----------------------------------------------------------------------------- topics
def _topic_table(topics: dict) -> str:
    """The bag's topics, one a line: name, message type, message count."""
    width = max((len(n) for n in topics), default=0)
    return "\n".join(f"  {name:<{width}}  {info.msgtype}  ({info.msgcount} message{'' if info.msgcount == 1 else 's'})"
                     for name, info in sorted(topics.items()))


def _pick(candidates: list[str], prefer) -> list[str]:
    """Narrow ambiguous candidates: a raw topic over its own transports, then ``prefer``."""
    raw = [c for c in candidates if not any(c.startswith(o + "/") for o in candidates if o != c)]
    if len(raw) == 1 or prefer is None:
        return raw
    preferred = [c for c in raw if prefer(c)]
    return preferred if len(preferred) == 1 else raw


def _choose_topic(path: Path, topics: dict, given: str | None, types: Sequence[str], what: str, flag: str,
                  accept=None, prefer=None) -> str:
    """The topic for ``what``: ``given`` (checked), else the one candidate of ``types`` that ``accept`` takes.

    Raises
    ------
    ValueError
        ``given`` is not in the bag or has another type; no or several candidates. The message lists
        the bag's topics and names ``flag``.
    """
    listing = f"; the bag's topics:\n{_topic_table(topics)}"
    if given is not None:
        if given not in topics:
            raise ValueError(f"{path}: no topic {given} ({flag}){listing}")
        if topics[given].msgtype not in types:
            raise ValueError(f"{path}: topic {given} ({flag}) is {topics[given].msgtype}, expected "
                             f"{' or '.join(types)}{listing}")
        return given
    candidates = sorted(n for n, info in topics.items() if info.msgtype in types and (accept is None or accept(n)))
    candidates = _pick(candidates, prefer) if len(candidates) > 1 else candidates
    if len(candidates) == 1:
        return candidates[0]
    kinds = " or ".join(types)
    if not candidates:
        raise ValueError(f"{path}: no {what} topic ({kinds}); pass {flag} TOPIC{listing}")
    raise ValueError(f"{path}: {len(candidates)} {what} topics ({kinds}): {', '.join(candidates)}; pass {flag} "
                     f"TOPIC to choose one{listing}")


def _namespace_distance(a: str, b: str) -> int:
    """How many namespace levels of ``a`` lie outside the namespace ``a`` and ``b`` share."""
    pa, pb = a.strip("/").split("/")[:-1], b.strip("/").split("/")[:-1]
    common = 0
    for x, y in zip(pa, pb):
        if x != y:
            break
        common += 1
    return len(pa) - common


def _camera_info_topic(path: Path, topics: dict, given: str | None, colour: str) -> str:
    """``given``, else the CameraInfo topic in (or nearest to) the colour topic's namespace."""
    infos = sorted(n for n, info in topics.items() if info.msgtype == CAMERA_INFO)
    if given is None and len(infos) > 1:
        dist = {n: _namespace_distance(colour, n) for n in infos}
        best = [n for n in infos if dist[n] == min(dist.values())]
        infos = best if len(best) == 1 else infos
        if len(infos) == 1:
            return infos[0]
    return _choose_topic(path, topics, given, (CAMERA_INFO,), "camera info", "--camera-info-topic")


# ----------------------------------------------------------------------------- the sequence
class _TopicIndex:
    """A topic's messages by header stamp: stamps (ns), receive times (ns), sorted by stamp."""

    def __init__(self, topic: str) -> None:
        self.topic = topic
        self.stamps: list[int] = []
        self.times: list[int] = []

    def sort(self) -> None:
        order = np.argsort(np.asarray(self.stamps, dtype=np.int64), kind="stable")
        self.stamps = np.asarray(self.stamps, dtype=np.int64)[order]
        self.times = np.asarray(self.times, dtype=np.int64)[order]


class RosBagSequence(_ImageSequence):
    """Lazy, random-access ROS bag (ROS 1, ROS 2 sqlite3/MCAP, MCAP file): ``len(seq)``, ``seq[i] -> Frame``.

    What is read, the topic defaults and the pose conventions: :mod:`semmatch.io.bags`. The
    depth must be registered to the colour camera (same size and intrinsics); the intrinsics
    are the colour topic's CameraInfo ``K``.

    Parameters
    ----------
    path : path
        The ``.bag`` file, the ROS 2 bag folder (``metadata.yaml`` + ``*.db3``/``*.mcap``), or an
        ``.mcap`` file.
    color_topic, depth_topic, camera_info_topic : str, optional
        Topics; default: chosen from the bag's topics by type and name (see the module).
    pose_topic : str, optional
        An Odometry, PoseStamped, PoseWithCovarianceStamped or TransformStamped topic; or ``/tf``
        (the TF tree, from its root above the camera unless ``pose_frames`` says otherwise).
    pose_frames : str, optional
        ``"WORLD:CAMERA"`` (or ``"WORLD"``): poses from ``/tf`` + ``/tf_static``. Not with ``pose_topic``.
    frames : slice, optional
        Use only these frames (indices of the colour/depth pairs in stamp order, e.g. ``slice(0, 500)``).
    max_difference : float
        Association window (seconds) for colour/depth header stamps.
    max_unmatched : float
        Fraction of colour frames allowed to have no depth partner (skipped with a warning).
    max_pose_gap : float
        Longest gap (seconds) between pose samples bridged by interpolation.
    labels : path, optional
        A labels folder ``000000.png ...`` indexed like the frames used.
    check_units : bool
        Check the median depth of up to 5 frames spread over the bag when it is opened, and of
        every frame read (:func:`semmatch.io.check_depth_units`).
    intrinsics : Intrinsics, optional
        The camera, instead of the CameraInfo topic (for bags without one).

    Attributes
    ----------
    timestamps : float64 (N,)
        Colour header stamps (seconds).
    depth_timestamps : float64 (N,)
        The paired depth header stamps.
    poses : float64 (N,4,4) or None
        ``T_world_camera`` per frame (NaN rows where unknown); None without a pose source.
    topics : dict
        ``{"color": ..., "depth": ..., "camera_info": ..., "pose": ...}`` as used.
    camera_frame : str
        The colour images' ``header.frame_id``.

    Raises
    ------
    FileNotFoundError
        No such path.
    ValueError
        Not a ROS bag; a topic missing, ambiguous or of the wrong type (the message lists the bag's
        topics and the flag to pass); no colour/depth pair; poses that cover no frame; frames
        whose depth is not in metres.
    """

    def __init__(
        self,
        path: PathLike,
        *,
        color_topic: str | None = None,
        depth_topic: str | None = None,
        camera_info_topic: str | None = None,
        pose_topic: str | None = None,
        pose_frames: str | None = None,
        frames: slice | None = None,
        max_difference: float = 0.02,
        max_unmatched: float = 0.05,
        max_pose_gap: float = 0.1,
        labels: PathLike | None = None,
        check_units: bool = True,
        intrinsics: Intrinsics | None = None,
    ) -> None:
        from ..runtime.progress import tqdm

        self.path = Path(path)
        if not self.path.exists():
            raise FileNotFoundError(f"{self.path}: no such ROS bag")
        if not is_rosbag(self.path):
            raise ValueError(f"{self.path}: not a ROS bag (a .bag file, an .mcap file, or a ROS 2 bag folder with "
                             "metadata.yaml and *.db3 or *.mcap)")
        self._lock = threading.Lock()
        self._readers: dict[tuple[int, int], tuple[object, dict]] = {}
        reader = self._reader()[0]
        topics = reader.topics
        images = (IMAGE, COMPRESSED_IMAGE)
        colour = _choose_topic(self.path, topics, color_topic, images, "colour", "--color-topic",
                               accept=lambda n: "depth" not in n.lower())
        depth = _choose_topic(self.path, topics, depth_topic, images, "depth", "--depth-topic",
                              accept=lambda n: "depth" in n.lower(),
                              prefer=lambda n: "aligned" in n.lower() or "registered" in n.lower())
        self.topics = {"color": colour, "depth": depth, "camera_info": None, "pose": pose_topic}
        self._cdr = reader.is2
        index = {t: _TopicIndex(t) for t in (colour, depth)}
        conns = [c for c in reader.connections if c.topic in index]
        total = topics[colour].msgcount + topics[depth].msgcount
        for conn, time, raw in tqdm(reader.messages(conns), total=total, desc=f"index {self.path.name}",
                                    unit="msg", leave=False, disable=total < 2000):
            ix = index[conn.topic]
            ix.stamps.append(_stamp_ns(raw, self._cdr))
            ix.times.append(time)
        for ix in index.values():
            if not ix.stamps:
                raise ValueError(f"{self.path}: topic {ix.topic} has no messages")
            ix.sort()
        self._colour, self._depth_ix = index[colour], index[depth]
        pairs = associate_frames(self._colour.stamps * 1e-9, self._depth_ix.stamps * 1e-9, max_difference,
                                 max_unmatched, rgb_where=f"{self.path}: colour topic {colour}",
                                 depth_where=f"depth topic {depth}")
        if frames is not None:
            pairs = pairs[frames]
            if not len(pairs):
                raise ValueError(f"{self.path}: no frames in {frames} (the bag has {len(self._colour.stamps)} "
                                 "colour/depth pairs)")
        self._pairs = pairs
        self.timestamps = self._colour.stamps[pairs[:, 0]] * 1e-9
        self.depth_timestamps = self._depth_ix.stamps[pairs[:, 1]] * 1e-9
        first = self._message(self._colour, int(pairs[0, 0]))
        self.camera_frame = tf_frame(first.header.frame_id)
        if intrinsics is None:
            info = _camera_info_topic(self.path, topics, camera_info_topic, colour)
            self.topics["camera_info"] = info
            msg = self._first_message(info)
            intrinsics = camera_info_intrinsics(msg, where=f"{self.path}: {info}")
        self.intrinsics = intrinsics
        self._check_registered()
        self.labels_dir = Path(labels) if labels is not None else None
        self.check_units = check_units
        if check_units:
            for k in np.unique(np.linspace(0, len(self) - 1, min(5, len(self))).round().astype(int)):
                _, depth_img, _, where = self._read_images(int(k))
                check_depth_units(depth_img, where=where)
        self.poses: np.ndarray | None = None
        if pose_topic is not None and topics.get(pose_topic) is not None and topics[pose_topic].msgtype in TF_TYPES:
            pose_topic, pose_frames = None, pose_frames or ""  # --pose-topic /tf: the TF tree
        if pose_topic is not None and pose_frames is not None:
            raise ValueError(f"{self.path}: give a pose topic ({pose_topic}) or TF frames ({pose_frames}), not both")
        if pose_topic is not None:
            self.poses = self._topic_poses(pose_topic, topics, max_pose_gap)
        elif pose_frames is not None:
            self.poses = self._tf_poses(pose_frames, reader, max_pose_gap)

    # ---- reading
    def _reader(self) -> tuple[object, dict]:
        """This thread's open reader of the bag and its connections by topic (opened on first use)."""
        key = (os.getpid(), threading.get_ident())
        with self._lock:
            got = self._readers.get(key)
        if got is None:
            self._close_finished_threads()
            reader = _open_reader(self.path)
            by_topic: dict[str, list] = {}
            for c in reader.connections:
                by_topic.setdefault(c.topic, []).append(c)
            got = (reader, by_topic)
            with self._lock:
                self._readers[key] = got
        return got

    def _close_finished_threads(self) -> None:
        """Close the readers of this process's threads that have ended (a thread pool's, after its work)."""
        alive = {t.ident for t in threading.enumerate()}
        with self._lock:
            gone = [k for k in self._readers if k[0] == os.getpid() and k[1] not in alive]
            readers = [self._readers.pop(k)[0] for k in gone]
        for reader in readers:
            reader.close()

    def _message(self, ix: _TopicIndex, k: int):
        """The ``k``-th message (in stamp order) of an indexed topic, deserialized."""
        reader, by_topic = self._reader()
        stamp, time = int(ix.stamps[k]), int(ix.times[k])
        for conn, _, raw in reader.messages(by_topic[ix.topic], start=time, stop=time + 1):
            if _stamp_ns(raw, self._cdr) == stamp:
                return reader.deserialize(raw, conn.msgtype)
        raise ValueError(f"{self.path}: topic {ix.topic} has no message stamped {stamp * 1e-9:.9f} at "
                         f"{time * 1e-9:.9f} any more (was the bag changed since it was opened?)")

    def _first_message(self, topic: str):
        """The first message of ``topic`` (by receive time)."""
        reader, by_topic = self._reader()
        for conn, _, raw in reader.messages(by_topic[topic]):
            return reader.deserialize(raw, conn.msgtype)
        raise ValueError(f"{self.path}: topic {topic} has no messages")

    def _read_images(self, i: int) -> tuple[np.ndarray, np.ndarray, str, str]:
        ci, di = int(self._pairs[i, 0]), int(self._pairs[i, 1])
        rp = f"{self.path}: {self._colour.topic} at {self._colour.stamps[ci] * 1e-9:.6f} (frame {i})"
        dp = f"{self.path}: {self._depth_ix.topic} at {self._depth_ix.stamps[di] * 1e-9:.6f} (frame {i})"
        rgb = decode_colour(self._message(self._colour, ci), rp)
        depth = decode_depth(self._message(self._depth_ix, di), dp)
        return rgb, depth, rp, dp

    def _check_registered(self) -> None:
        """Refuse depth of another size than the colour; warn when the two name different frames.

        semmatch reads depth pixel by pixel with the colour image: depth that is not registered to
        the colour camera (a RealSense's ``/camera/depth/image_rect_raw``) puts every label in the
        wrong place.
        """
        rgb, depth, rp, dp = self._read_images(0)
        hint = ("the depth is not registered to the colour camera; record and pass (--depth-topic) the registered "
                "depth (RealSense: aligned_depth_to_color, OpenNI: depth_registered)")
        if depth.shape != rgb.shape[:2]:
            raise ValueError(f"{dp}: depth images are {depth.shape[1]}x{depth.shape[0]}, the colour images "
                             f"{rgb.shape[1]}x{rgb.shape[0]} ({self._colour.topic}): {hint}")
        depth_frame = tf_frame(self._message(self._depth_ix, int(self._pairs[0, 1])).header.frame_id)
        if depth_frame and self.camera_frame and depth_frame != self.camera_frame:
            warnings.warn(f"{self.path}: depth topic {self._depth_ix.topic} is in frame {depth_frame!r}, colour topic "
                          f"{self._colour.topic} in {self.camera_frame!r}: if {hint}", UserWarning, stacklevel=3)

    def __len__(self) -> int:
        return len(self._pairs)

    def frame_files(self, i: int) -> tuple[Path, ...]:
        """The files frame ``i`` is read from: the bag's (every frame shares them).

        A ``.bag`` or ``.mcap`` file itself; a ROS 2 bag folder's ``metadata.yaml`` and storage
        files. Caches keyed on files (the ``--estimate-poses`` cache) then key a bag on their sizes and
        times, and a frame range or topic choice on the frames' stamps and :attr:`topics`.
        """
        frame_index(i, len(self))
        if self.path.is_file():
            return (self.path,)
        return tuple(sorted(f for f in self.path.iterdir() if f.name == "metadata.yaml" or f.name.endswith(
            (".db3", ".mcap", ".db3.zstd", ".mcap.zstd"))))

    # ---- poses
    def _check_pose_cover(self, poses: np.ndarray, where: str) -> None:
        """Refuse poses that cover no frame (the message gives the frames' time span)."""
        if not np.isfinite(poses[:, 0, 0]).any():
            raise ValueError(f"{where}: the poses cover none of the {len(self)} frames "
                             f"({self.timestamps[0]:.3f}..{self.timestamps[-1]:.3f}; gaps over the pose samples "
                             "longer than max_pose_gap are not bridged)")

    def _tf_poses(self, spec: str, reader, max_gap: float) -> np.ndarray:
        """Poses from the TF tree: ``spec`` is ``WORLD:CAMERA``, ``WORLD`` (the images' frame as CAMERA) or
        ``""`` (also WORLD left to the tree: the root above the camera)."""
        world, _, camera = spec.partition(":")
        camera = tf_frame(camera or self.camera_frame)
        if not camera:
            raise ValueError(f"{self.path}: the colour images name no frame (header.frame_id); pass --pose-frames "
                             "WORLD:CAMERA")
        tree = TfTree(reader)
        world = tf_frame(world) or tree.root(camera)
        where = f"{self.path}: /tf {world} -> {camera}"
        if world == camera:
            raise ValueError(f"{where}: /tf and /tf_static give {camera!r} no parent frame (their frames: "
                             f"{', '.join(tree.frames()) or 'none'}); pass --pose-frames WORLD:CAMERA")
        self.topics["pose"] = f"/tf {world} -> {camera}"
        poses = tree.lookup(world, camera, self.timestamps, max_gap, where)
        self._check_pose_cover(poses, where)
        return poses

    def _topic_poses(self, topic: str, topics: dict, max_gap: float) -> np.ndarray:
        """Poses from a pose topic, composed with the TF chain to the camera where it poses another frame."""
        _choose_topic(self.path, topics, topic, POSE_TYPES, "pose", "--pose-topic")
        reader, by_topic = self._reader()
        stamps, poses, child = [], [], ""
        for conn, _, raw in reader.messages(by_topic[topic]):
            msg = reader.deserialize(raw, conn.msgtype)
            T, _, child = pose_of(msg)
            stamps.append(stamp_seconds(msg))
            poses.append(T)
        where = f"{self.path}: {topic}"
        if not stamps:
            raise ValueError(f"{where}: the pose topic has no messages")
        out = interpolate_poses(self.timestamps, np.asarray(stamps), np.asarray(poses), max_gap)
        if child and self.camera_frame and child != self.camera_frame:
            tree = TfTree(reader)
            if tree.path(child, self.camera_frame) is None:
                raise ValueError(f"{where}: the poses are of frame {child!r}, the colour images are in "
                                 f"{self.camera_frame!r}, and /tf and /tf_static connect no chain between them "
                                 f"(their frames: {', '.join(tree.frames()) or 'none'}); pass --pose-frames "
                                 f"WORLD:{self.camera_frame} instead, or record the camera's static transforms")
            out = out @ tree.lookup(child, self.camera_frame, self.timestamps, max_gap, where)
        self._check_pose_cover(out, where)
        return out

    # ---- life cycle
    def close(self) -> None:
        """Close the bag readers this sequence opened (it reopens them when read again)."""
        with self._lock:
            readers, self._readers = self._readers, {}
        for (pid, _), (reader, _) in readers.items():
            if pid == os.getpid():
                reader.close()

    def __enter__(self) -> RosBagSequence:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __getstate__(self) -> dict:
        state = self.__dict__.copy()
        state["_readers"], state["_lock"] = {}, None
        return state

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self._lock = threading.Lock()


def read_rosbag(path: PathLike, **kwargs) -> RosBagSequence:
    """Open a ROS bag as a sequence (see :class:`RosBagSequence`)."""
    return RosBagSequence(path, **kwargs)
