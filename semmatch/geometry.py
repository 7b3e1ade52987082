"""Camera geometry: intrinsics, poses, back-projection, projection and voxel keys.

Conventions (docs/data.md): world in metres with z up; camera frame OpenCV (x right, y down,
z forward); a pose is ``T_world_camera`` (4x4, camera to world).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

__all__ = [
    "Intrinsics",
    "DEFAULT_INTRINSICS",
    "check_pose",
    "quat_to_rotation",
    "rotation_to_quat",
    "pose_from_tum",
    "pose_to_tum",
    "look_at",
    "backproject",
    "pixel_rays",
    "project",
    "transform",
    "voxel_keys",
    "pack_keys",
    "unpack_keys",
]


#: largest image (pixels) an :class:`Intrinsics` accepts: 8K is 33 M; a frame costs ~40 bytes a pixel
MAX_PIXELS = 64 * 2**20


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics of a depth-registered RGB-D camera.

    Parameters
    ----------
    width, height : int
        Image size in pixels.
    fx, fy, cx, cy : float
        Focal lengths and principal point in pixels.
    depth_scale : float
        Depth PNG value per metre (1000 = millimetres).
    """

    width: int = 640
    height: int = 480
    fx: float = 268.51
    fy: float = 268.51
    cx: float = 320.0
    cy: float = 240.0
    depth_scale: float = 1000.0

    def __post_init__(self) -> None:
        if int(self.width) <= 0 or int(self.height) <= 0:
            raise ValueError(f"image size must be positive, got {self.width}x{self.height}")
        if int(self.width) * int(self.height) > MAX_PIXELS:
            raise ValueError(f"image size {self.width}x{self.height} ({int(self.width) * int(self.height):,} pixels) "
                             f"is larger than any RGB-D camera's (limit {MAX_PIXELS:,} pixels)")
        for name in ("fx", "fy"):
            v = float(getattr(self, name))
            if not np.isfinite(v) or v <= 0:
                raise ValueError(f"focal length {name} must be > 0, got {v}")
        for name in ("cx", "cy"):
            if not np.isfinite(float(getattr(self, name))):
                raise ValueError(f"principal point {name} must be finite")
        if not float(self.depth_scale) > 0:
            raise ValueError(f"depth_scale must be > 0, got {self.depth_scale}")

    @property
    def K(self) -> np.ndarray:
        """The 3x3 camera matrix."""
        return np.array(
            [[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]], dtype=np.float64
        )

    @property
    def shape(self) -> tuple[int, int]:
        """``(height, width)``."""
        return int(self.height), int(self.width)

    def to_dict(self) -> dict:
        """Return the ``intrinsics.json`` dictionary."""
        d = asdict(self)
        d["width"], d["height"] = int(self.width), int(self.height)
        return d

    @classmethod
    def from_dict(cls, d: dict) -> Intrinsics:
        """Build from an ``intrinsics.json`` dictionary (``depth_scale`` defaults to 1000)."""
        missing = [k for k in ("width", "height", "fx", "fy", "cx", "cy") if k not in d]
        if missing:
            raise ValueError(f"intrinsics lack {', '.join(missing)}")
        return cls(
            width=int(d["width"]),
            height=int(d["height"]),
            fx=float(d["fx"]),
            fy=float(d["fy"]),
            cx=float(d["cx"]),
            cy=float(d["cy"]),
            depth_scale=float(d.get("depth_scale", 1000.0)),
        )

    def scaled(self, width: int, height: int) -> Intrinsics:
        """Intrinsics of the same camera resampled to ``width`` x ``height``."""
        sx, sy = width / self.width, height / self.height
        return Intrinsics(
            width, height, self.fx * sx, self.fy * sy,
            (self.cx + 0.5) * sx - 0.5, (self.cy + 0.5) * sy - 0.5, self.depth_scale,
        )


#: The paper's Habitat camera: 640x480, fx = fy = 268.51, principal point at the centre.
DEFAULT_INTRINSICS = Intrinsics()


def check_pose(pose: np.ndarray, *, what: str = "pose", atol: float = 1e-4) -> np.ndarray:
    """Validate a 4x4 rigid transform and return it as float64.

    Raises
    ------
    ValueError
        If the matrix is not 4x4, holds NaN/inf, its last row is not ``0 0 0 1`` or its
        rotation block is not a rotation (orthonormal with determinant +1).
    """
    T = np.asarray(pose, dtype=np.float64)
    if T.shape != (4, 4):
        raise ValueError(f"{what}: expected a 4x4 matrix, got shape {T.shape}")
    if not np.isfinite(T).all():
        raise ValueError(f"{what}: holds NaN or inf")
    if not np.allclose(T[3], [0, 0, 0, 1], atol=atol):
        raise ValueError(f"{what}: last row must be [0 0 0 1], got {T[3]}")
    R = T[:3, :3]
    if not np.allclose(R.T @ R, np.eye(3), atol=1e-3) or np.linalg.det(R) < 0:
        raise ValueError(f"{what}: the 3x3 block is not a rotation matrix")
    return T


def quat_to_rotation(q: np.ndarray) -> np.ndarray:
    """Rotation matrices from unit quaternions ``(qx, qy, qz, qw)``; shape (..., 4) -> (..., 3, 3)."""
    q = np.asarray(q, dtype=np.float64)
    n = np.linalg.norm(q, axis=-1, keepdims=True)
    if np.any(n < 1e-12) or not np.isfinite(q).all():
        raise ValueError("quaternion must be finite and non-zero")
    x, y, z, w = np.moveaxis(q / n, -1, 0)
    R = np.stack(
        [
            1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w),
            2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w),
            2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y),
        ],
        axis=-1,
    )
    return R.reshape(q.shape[:-1] + (3, 3))


def rotation_to_quat(R: np.ndarray) -> np.ndarray:
    """Unit quaternion ``(qx, qy, qz, qw)`` with ``qw >= 0`` of a 3x3 rotation matrix."""
    R = np.asarray(R, dtype=np.float64)
    tr = np.trace(R)
    if tr > 0:
        s = np.sqrt(tr + 1.0) * 2
        q = [(R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s, 0.25 * s]
    elif R[0, 0] > R[1, 1] and R[0, 0] > R[2, 2]:
        s = np.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2]) * 2
        q = [0.25 * s, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s, (R[2, 1] - R[1, 2]) / s]
    elif R[1, 1] > R[2, 2]:
        s = np.sqrt(1.0 + R[1, 1] - R[0, 0] - R[2, 2]) * 2
        q = [(R[0, 1] + R[1, 0]) / s, 0.25 * s, (R[1, 2] + R[2, 1]) / s, (R[0, 2] - R[2, 0]) / s]
    else:
        s = np.sqrt(1.0 + R[2, 2] - R[0, 0] - R[1, 1]) * 2
        q = [(R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, 0.25 * s, (R[1, 0] - R[0, 1]) / s]
    q = np.asarray(q)
    q /= np.linalg.norm(q)
    return -q if q[3] < 0 else q


def pose_from_tum(values: np.ndarray) -> np.ndarray:
    """4x4 pose from TUM values ``tx ty tz qx qy qz qw``."""
    v = np.asarray(values, dtype=np.float64)
    T = np.eye(4)
    T[:3, :3] = quat_to_rotation(v[3:7])
    T[:3, 3] = v[:3]
    return T


def pose_to_tum(pose: np.ndarray) -> np.ndarray:
    """TUM values ``tx ty tz qx qy qz qw`` of a 4x4 pose."""
    T = check_pose(pose)
    return np.concatenate([T[:3, 3], rotation_to_quat(T[:3, :3])])


def look_at(eye: np.ndarray, target: np.ndarray, up: np.ndarray = (0.0, 0.0, 1.0)) -> np.ndarray:
    """Camera pose ``T_world_camera`` at ``eye`` looking at ``target`` (OpenCV camera axes)."""
    eye = np.asarray(eye, dtype=np.float64)
    z = np.asarray(target, dtype=np.float64) - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, np.asarray(up, dtype=np.float64))
    if np.linalg.norm(x) < 1e-9:
        raise ValueError("look_at: viewing direction is parallel to the up vector")
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3] = x, y, z, eye
    return T


def pixel_rays(intr: Intrinsics, stride: int = 1) -> np.ndarray:
    """Camera-frame ray directions with ``z = 1`` for every ``stride``-th pixel, shape (h, w, 3)."""
    v, u = np.mgrid[0 : intr.height : stride, 0 : intr.width : stride].astype(np.float32)
    x = (u - np.float32(intr.cx)) / np.float32(intr.fx)
    y = (v - np.float32(intr.cy)) / np.float32(intr.fy)
    return np.stack([x, y, np.ones_like(x)], axis=-1)


def transform(points: np.ndarray, T: np.ndarray) -> np.ndarray:
    """Apply a 4x4 rigid transform to (N,3) points (float32 result for float32 input)."""
    T = np.asarray(T)
    dtype = points.dtype if np.issubdtype(points.dtype, np.floating) else np.float64
    return (points @ T[:3, :3].T.astype(dtype)) + T[:3, 3].astype(dtype)


def backproject(
    depth: np.ndarray,
    intr: Intrinsics,
    pose: np.ndarray | None = None,
    *,
    stride: int = 1,
    max_depth: float | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Back-project a depth image to 3D points.

    Parameters
    ----------
    depth : ndarray, shape (H, W)
        Metric depth (float, metres); 0 or non-finite = no measurement.
    intr : Intrinsics
        Camera intrinsics; ``(H, W)`` must match.
    pose : ndarray (4, 4), optional
        ``T_world_camera``; points are returned in the world frame when given.
    stride : int
        Keep every ``stride``-th pixel in each direction.
    max_depth : float, optional
        Ignore measurements beyond this distance.

    Returns
    -------
    points : ndarray of float32, shape (N, 3)
    index : ndarray of int64, shape (N,)
        Flat pixel index ``v * W + u`` of each point in the full-resolution image.
    """
    depth = np.asarray(depth)
    if depth.shape != intr.shape:
        raise ValueError(f"depth is {depth.shape[::-1]} (WxH) but intrinsics say {intr.width}x{intr.height}")
    d = depth[::stride, ::stride].astype(np.float32, copy=False)
    valid = np.isfinite(d) & (d > 0)
    if max_depth is not None:
        valid &= d <= max_depth
    rows, cols = np.nonzero(valid)
    z = d[rows, cols]
    v = rows * stride
    u = cols * stride
    x = (u.astype(np.float32) - np.float32(intr.cx)) * (z / np.float32(intr.fx))
    y = (v.astype(np.float32) - np.float32(intr.cy)) * (z / np.float32(intr.fy))
    pts = np.stack([x, y, z], axis=1)
    if pose is not None:
        pts = transform(pts, check_pose(pose)).astype(np.float32)
    return pts, v.astype(np.int64) * intr.width + u


def project(
    points: np.ndarray, intr: Intrinsics, pose: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Project 3D points into the image.

    Parameters
    ----------
    points : ndarray, shape (N, 3)
        World points (camera points when ``pose`` is None).
    intr : Intrinsics
    pose : ndarray (4, 4), optional
        ``T_world_camera``.

    Returns
    -------
    uv : ndarray of float64, shape (N, 2)
        Pixel coordinates ``(u, v)``; ``(u, v) = (0, 0)`` is the centre of the top-left pixel.
    z : ndarray of float64, shape (N,)
        Depth along the optical axis (<= 0: behind the camera).
    """
    p = np.asarray(points, dtype=np.float64)
    if pose is not None:
        p = transform(p, np.linalg.inv(check_pose(pose)))
    z = p[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        u = intr.fx * p[:, 0] / z + intr.cx
        v = intr.fy * p[:, 1] / z + intr.cy
    return np.stack([u, v], axis=1), z


def voxel_keys(points: np.ndarray, voxel_size: float, origin: np.ndarray | None = None) -> np.ndarray:
    """Integer voxel coordinates ``floor((xyz - origin) / voxel_size)``, shape (N, 3) int64."""
    if not voxel_size > 0:
        raise ValueError(f"voxel_size must be > 0, got {voxel_size}")
    p = np.asarray(points, dtype=np.float64)
    if origin is not None:
        p = p - np.asarray(origin, dtype=np.float64)
    return np.floor(p / voxel_size).astype(np.int64)


def pack_keys(keys: np.ndarray) -> np.ndarray:
    """Pack (N,3) int64 voxel coordinates into one int64 per voxel (21 bits per axis).

    Coordinates must lie in ``[-2**20, 2**20)``: about ±52 km at 5 cm voxels.
    """
    k = np.asarray(keys, dtype=np.int64)
    lim = 1 << 20
    if k.size and (k.min() < -lim or k.max() >= lim):
        raise ValueError("voxel coordinates out of the packable range ±2**20")
    k = k + lim
    return (k[:, 0] << 42) | (k[:, 1] << 21) | k[:, 2]


def unpack_keys(packed: np.ndarray) -> np.ndarray:
    """Inverse of :func:`pack_keys`: (N,) int64 packed keys to (N,3) int64 voxel coordinates."""
    p = np.asarray(packed, dtype=np.int64)
    mask = (1 << 21) - 1
    return np.stack([(p >> 42) & mask, (p >> 21) & mask, p & mask], axis=1) - (1 << 20)
