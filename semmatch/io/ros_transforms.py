"""ROS poses and transforms as 4x4 matrices: pose messages, the TF tree of ``/tf`` and ``/tf_static``.

:func:`pose_of` reads a pose message (Odometry, PoseStamped, PoseWithCovarianceStamped,
TransformStamped) as ``T_parent_child``; :class:`TfTree` holds a bag's transforms and composes
the chain between two frames at given times (:func:`semmatch.io.timestamps.interpolate_poses`
along each moving edge); :func:`transform_message` and :func:`pose_message` write them back.
ROS's convention: a transform with ``header.frame_id`` PARENT and ``child_frame_id`` CHILD is
the pose of CHILD in PARENT, ``T_parent_child``.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from .geometry import pose_to_tum, quat_to_rotation
from .timestamps import interpolate_poses

__all__ = [
    "POSE_TYPES",
    "TF_TYPES",
    "TF_TOPICS",
    "LINK_TO_OPTICAL",
    "stamp_seconds",
    "tf_frame",
    "transform_matrix",
    "pose_of",
    "TfTree",
    "transform_message",
    "pose_message",
]

ODOMETRY = "nav_msgs/msg/Odometry"
POSE_STAMPED = "geometry_msgs/msg/PoseStamped"
POSE_COV_STAMPED = "geometry_msgs/msg/PoseWithCovarianceStamped"
TRANSFORM_STAMPED = "geometry_msgs/msg/TransformStamped"
#: message types a pose topic may have
POSE_TYPES = (ODOMETRY, POSE_STAMPED, POSE_COV_STAMPED, TRANSFORM_STAMPED)
#: message types of ``/tf`` and ``/tf_static`` (ROS 2 and ROS 1's tf2, ROS 1's old tf)
TF_TYPES = ("tf2_msgs/msg/TFMessage", "tf/msg/tfMessage")
TF_TOPICS = ("/tf", "/tf_static")
#: ROS's camera_link (x forward, y left, z up) to its optical frame (x right, y down, z forward)
LINK_TO_OPTICAL = np.array([[0.0, 0.0, 1.0, 0.0], [-1.0, 0.0, 0.0, 0.0], [0.0, -1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]])


def stamp_seconds(msg) -> float:
    """A message header's stamp in seconds (as ``ns * 1e-9``, like the images' stamps: equal stamps stay equal)."""
    return (msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec) * 1e-9


def tf_frame(name: str) -> str:
    """A TF frame name without ROS 1's leading slash."""
    return name.lstrip("/")



def transform_matrix(translation, rotation) -> np.ndarray:
    """A 4x4 from a ROS translation (x, y, z) and quaternion (x, y, z, w)."""
    T = np.eye(4)
    T[:3, :3] = quat_to_rotation(np.array([rotation.x, rotation.y, rotation.z, rotation.w], dtype=np.float64))
    T[:3, 3] = (translation.x, translation.y, translation.z)
    return T


def pose_of(msg) -> tuple[np.ndarray, str, str]:
    """A pose message's ``T_parent_child``, parent frame and child frame ("" when the message names none)."""
    parent = tf_frame(msg.header.frame_id)
    if msg.__msgtype__ == TRANSFORM_STAMPED:
        return transform_matrix(msg.transform.translation, msg.transform.rotation), parent, tf_frame(
            msg.child_frame_id)
    pose = msg.pose.pose if msg.__msgtype__ in (ODOMETRY, POSE_COV_STAMPED) else msg.pose
    child = tf_frame(msg.child_frame_id) if msg.__msgtype__ == ODOMETRY else ""
    return transform_matrix(pose.position, pose.orientation), parent, child


class TfTree:
    """The transforms of ``/tf`` (time series per edge) and ``/tf_static`` (one per edge) of a bag."""

    def __init__(self, reader) -> None:
        self.dynamic: dict[tuple[str, str], tuple[list[float], list[np.ndarray]]] = {}
        self.static: dict[tuple[str, str], np.ndarray] = {}
        conns = [c for c in reader.connections if c.topic in TF_TOPICS and c.msgtype in TF_TYPES]
        for conn, _, raw in reader.messages(conns) if conns else ():  # no connections would read every topic
            msg = reader.deserialize(raw, conn.msgtype)
            for tf in msg.transforms:
                edge = (tf_frame(tf.header.frame_id), tf_frame(tf.child_frame_id))
                T = transform_matrix(tf.transform.translation, tf.transform.rotation)
                if conn.topic == "/tf_static":
                    self.static[edge] = T
                else:
                    ts, Ts = self.dynamic.setdefault(edge, ([], []))
                    ts.append(stamp_seconds(tf))
                    Ts.append(T)

    def frames(self) -> list[str]:
        """Every frame the tree names."""
        return sorted({f for e in (*self.static, *self.dynamic) for f in e})

    def root(self, frame: str) -> str:
        """The top of ``frame``'s tree (following parents; ``frame`` itself when it has none)."""
        parents = {b: a for a, b in (*self.static, *self.dynamic)}
        seen = {frame}
        while frame in parents and parents[frame] not in seen:
            frame = parents[frame]
            seen.add(frame)
        return frame

    def path(self, parent: str, child: str) -> list[tuple[str, str, bool]] | None:
        """The edges from ``parent`` to ``child`` as ``(a, b, forward)``; None when they are not connected."""
        links: dict[str, list[tuple[str, bool]]] = {}
        for a, b in (*self.static, *self.dynamic):
            links.setdefault(a, []).append((b, True))
            links.setdefault(b, []).append((a, False))
        came: dict[str, tuple[str, bool] | None] = {parent: None}
        todo = deque([parent])
        while todo:
            f = todo.popleft()
            for g, forward in links.get(f, []):
                if g not in came:
                    came[g] = (f, forward)
                    todo.append(g)
        if child not in came:
            return None
        edges = []
        f = child
        while came[f] is not None:
            prev, forward = came[f]
            edges.append((prev, f, forward))
            f = prev
        return edges[::-1]

    def lookup(self, parent: str, child: str, stamps: np.ndarray, max_gap: float, where: str) -> np.ndarray:
        """``T_parent_child`` at ``stamps`` (N,4,4) along the tree's chain; NaN where an edge has no sample.

        Raises
        ------
        ValueError
            The two frames are not connected (the message lists the tree's frames).
        """
        edges = self.path(parent, child)
        if edges is None:
            raise ValueError(f"{where}: /tf and /tf_static connect no chain from {parent!r} to {child!r}; "
                             f"their frames: {', '.join(self.frames()) or 'none'}")
        out = np.broadcast_to(np.eye(4), (len(stamps), 4, 4)).copy()
        for a, b, forward in edges:
            key = (a, b) if forward else (b, a)
            if key in self.dynamic:
                ts, Ts = self.dynamic[key]
                T = interpolate_poses(stamps, np.asarray(ts), np.asarray(Ts), max_gap)
            else:
                T = np.broadcast_to(self.static[key], (len(stamps), 4, 4))
            if not forward:
                T = np.linalg.inv(T)  # NaN stays NaN
            out = out @ T
        return out




def transform_message(types: dict, header, child: str, T: np.ndarray):
    """A ``geometry_msgs/TransformStamped`` of ``T_parent_child`` (``header.frame_id`` = parent).

    Parameters
    ----------
    types : dict
        Message classes of a rosbags typestore (``typestore.types``).
    header : std_msgs/Header
    child : str
    T : (4,4) rigid transform
    """
    q = pose_to_tum(T)  # tx ty tz qx qy qz qw
    Vector3, Quaternion = types["geometry_msgs/msg/Vector3"], types["geometry_msgs/msg/Quaternion"]
    tf = types["geometry_msgs/msg/Transform"](Vector3(*q[:3]), Quaternion(*q[3:]))
    return types["geometry_msgs/msg/TransformStamped"](header, child, tf)


def pose_message(types: dict, T: np.ndarray):
    """A ``geometry_msgs/Pose`` of the rigid transform ``T`` (``types``: a typestore's message classes)."""
    q = pose_to_tum(T)
    return types["geometry_msgs/msg/Pose"](types["geometry_msgs/msg/Point"](*q[:3]),
                                           types["geometry_msgs/msg/Quaternion"](*q[3:]))
