"""Floors of maps and the up direction of a recording: what levels two maps before they are aligned.

:func:`fit_floor` finds a map's floor (the lowest well-supported layer of points facing up,
refined by a RANSAC plane) as a :class:`Floor`, whose :meth:`Floor.levelling` puts it at z = 0;
:func:`camera_up` (a trajectory's cameras) and :func:`label_up` (a map's floor-labelled points)
give the up hints it starts from. Used by :mod:`semmatch.poses.alignment`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..io import SemanticMap

__all__ = ["Floor", "fit_floor", "camera_up", "label_up"]


@dataclass(frozen=True)
class Floor:
    """A floor plane fitted in one map's frame: points ``x`` with ``normal @ x + offset = 0``.

    Attributes
    ----------
    normal : ndarray (3,)
        Unit normal, pointing up (towards the room).
    offset : float
    residual : float
        RMS distance (m) of the plane's inliers from it.
    support : float
        Share of the map's (downsampled) points on the plane.
    up_angle_deg : float
        Angle between the normal and the up hint.
    """

    normal: np.ndarray
    offset: float
    residual: float
    support: float
    up_angle_deg: float

    def levelling(self) -> np.ndarray:
        """Rigid transform taking this map's frame to one with the floor at z = 0 and its normal +z."""
        n = self.normal / np.linalg.norm(self.normal)
        z = np.array([0.0, 0.0, 1.0])
        v, c = np.cross(n, z), float(n @ z)
        if np.linalg.norm(v) < 1e-12:
            R = np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
        else:
            K = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
            R = np.eye(3) + K + K @ K / (1.0 + c)
        L = np.eye(4)
        L[:3, :3] = R
        L[:3, 3] = -R @ (-self.offset * n)  # a point of the plane goes to the origin's height
        return L

    def as_dict(self) -> dict:
        """JSON-ready fields."""
        return {"normal": [float(v) for v in self.normal], "offset": float(self.offset),
                "residual": float(self.residual), "support": float(self.support),
                "up_angle_deg": float(self.up_angle_deg)}


def camera_up(poses: np.ndarray) -> np.ndarray:
    """The mean up direction of a trajectory's cameras (``-y`` of each camera), a map's up hint.

    Parameters
    ----------
    poses : ndarray (N, 4, 4)
        ``T_world_camera`` (OpenCV camera: x right, y down, z forward); non-finite rows skipped.

    Returns
    -------
    ndarray (3,)
        Unit vector in the poses' frame.

    Raises
    ------
    ValueError
        No finite pose.
    """
    P = np.asarray(poses, dtype=np.float64)
    ok = np.isfinite(P).all(axis=(1, 2))
    if not ok.any():
        raise ValueError("no finite pose to take the cameras' up direction from")
    up = -P[ok, :3, 1].mean(axis=0)
    return up / np.linalg.norm(up)


def label_up(m: SemanticMap) -> np.ndarray | None:
    """A map's up hint from its floor-labelled points: their plane's normal, towards the other points.

    Returns None when fewer than 100 points are labelled floor (or the map has no labels).
    """
    from ..io.labels import NAMES

    if m.labels is None:
        return None
    pts = m.points[np.asarray(m.labels) == NAMES.index("floor")].astype(np.float64)
    if len(pts) < 100:
        return None
    c = pts.mean(axis=0)
    n = np.linalg.svd(pts - c, full_matrices=False)[2][2]
    if np.median((m.points.astype(np.float64) - c) @ n) < 0:
        n = -n
    return n / np.linalg.norm(n)


def fit_floor(cloud, up: np.ndarray, voxel_size: float, *, floor_angle: float = 30.0, min_support: float = 0.03,
              max_below: float = 0.02, seed: int = 0) -> Floor | None:
    """The floor of a map: the lowest well-supported layer of points facing up, refined by a RANSAC plane.

    Parameters
    ----------
    cloud : open3d.geometry.PointCloud
        Downsampled at ``voxel_size``, with normals.
    up : array-like (3,)
        Up hint in the cloud's frame (e.g. :func:`camera_up`); need not be exact.
    voxel_size : float
        Layer thickness (m) and the plane's inlier distance (half of it).
    floor_angle : float
        Largest angle (degrees) between a floor normal (point or plane) and ``up``.
    min_support : float
        Smallest share of the cloud's points on the floor.
    max_below : float
        Largest share of the cloud's points more than two voxels below the plane (a map that
        sees too little floor finds a table or bed top instead, with the floor's points under it).
    seed : int
        Seed of Open3D's RANSAC (``segment_plane``).

    Returns
    -------
    Floor or None
        None: no such layer.
    """
    import open3d as o3d

    up = np.asarray(up, dtype=np.float64)
    up = up / np.linalg.norm(up)
    pts = np.asarray(cloud.points)
    nrm = np.asarray(cloud.normals)
    if len(pts) < 10 or len(nrm) != len(pts):
        return None
    cos = np.cos(np.radians(floor_angle))
    flat = np.abs(nrm @ up) >= cos
    if flat.sum() < max(10, min_support * len(pts)):
        return None
    h = pts[flat] @ up
    bins = np.floor((h - h.min()) / voxel_size).astype(int)
    counts = np.bincount(bins)
    need = max(20, min_support * len(pts) / 2)
    # the lowest layer (two bins thick) holding enough points: below it only noise
    pair = counts + np.r_[counts[1:], 0]
    low = np.flatnonzero(pair >= need)
    if len(low) == 0:
        return None
    lo = h.min() + low[0] * voxel_size
    band = (h >= lo - 0.5 * voxel_size) & (h <= lo + 2 * voxel_size)  # a table top 0.3 m up stays out
    sel = pts[flat][band]
    if len(sel) < 10:
        return None
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(sel))
    o3d.utility.random.seed(int(seed))
    plane, inl = pc.segment_plane(distance_threshold=0.5 * voxel_size, ransac_n=3, num_iterations=1000)
    n, d = np.asarray(plane[:3], dtype=np.float64), float(plane[3])
    s = np.linalg.norm(n)
    n, d = n / s, d / s
    if n @ up < 0:
        n, d = -n, -d
    angle = float(np.degrees(np.arccos(np.clip(n @ up, -1.0, 1.0))))
    # support: every point of the cloud on the plane (not only those of the band)
    dist = pts @ n + d
    support = float((np.abs(dist) <= 0.5 * voxel_size).mean())
    if angle > floor_angle or support < min_support:
        return None
    if (dist < -2 * voxel_size).mean() > max_below:  # a floor has nothing under it (a bed top has)
        return None
    res = float(np.sqrt(np.mean((sel[inl] @ n + d) ** 2)))
    return Floor(normal=n, offset=d, residual=res, support=support, up_angle_deg=angle)
