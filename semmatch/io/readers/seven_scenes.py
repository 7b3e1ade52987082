"""Microsoft 7-Scenes folders (also the layout of andyzeng/tsdf-fusion-python's data)::

    <folder>/frame-000000.color.png|jpg   colour
    <folder>/frame-000000.depth.png       16-bit depth in millimetres (65535 = no measurement)
    <folder>/frame-000000.pose.txt        optional: 4x4 T_world_camera (inf/NaN = unknown)
    <folder>/camera-intrinsics.txt        optional: the 3x3 camera matrix
    <folder>/intrinsics.json              optional: our intrinsics file (wins over both)
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..geometry import Intrinsics
from ..images import read_image
from ..reading_checks import check_depth_scale, check_poses
from .base import ImageSequence

__all__ = ["SEVEN_SCENES_INTRINSICS", "is_7scenes", "SevenScenesSequence"]

PathLike = str | os.PathLike

#: Microsoft 7-Scenes Kinect (its published camera matrix; depth PNGs in millimetres)
SEVEN_SCENES_INTRINSICS = Intrinsics(640, 480, 585.0, 585.0, 320.0, 240.0, 1000.0)


def is_7scenes(path: PathLike) -> bool:
    """True when ``path`` is a folder with 7-Scenes frames (``frame-000000.depth.png`` ...)."""
    p = Path(path)
    return p.is_dir() and next(p.glob("frame-*.depth.png"), None) is not None


def _read_matrix(path: Path, n: int, what: str) -> np.ndarray:
    """An ``n`` x ``n`` matrix of numbers from a text file (the message names the file)."""
    try:
        M = np.loadtxt(path, dtype=np.float64)
    except ValueError as e:
        raise ValueError(f"{path}: not a {what} ({e})") from None
    if M.shape != (n, n):
        raise ValueError(f"{path}: expected a {what} ({n}x{n}), got shape {M.shape}")
    return M


def _read_pose_txt(path: Path) -> np.ndarray:
    """A 7-Scenes ``frame-*.pose.txt`` (4x4); NaN when it is missing or holds inf/NaN (unknown pose).

    A finite pose is checked (:func:`~semmatch.io.reading_checks.check_poses`): a translation of
    1e30 or 200 km, or a block that is no rotation, is refused with the file named.
    """
    if not path.is_file():
        return np.full((4, 4), np.nan)
    T = _read_matrix(path, 4, "4x4 pose")
    if not np.isfinite(T).all():
        return np.full((4, 4), np.nan)
    check_poses(T[None], where=str(path), names=[str(path)])
    return T


def _read_camera_matrix(path: Path, width: int, height: int, depth_scale: float) -> Intrinsics:
    K = _read_matrix(path, 3, "3x3 camera matrix")
    return Intrinsics(width, height, K[0, 0], K[1, 1], K[0, 2], K[1, 2], depth_scale)


class SevenScenesSequence(ImageSequence):
    """Lazy, random-access 7-Scenes folder: ``frame-XXXXXX.color.*``, ``.depth.png``, ``.pose.txt``.

    Parameters
    ----------
    path : path
        The folder (one 7-Scenes ``seq-NN`` folder, or andyzeng/tsdf-fusion-python's ``data``).
    intrinsics : Intrinsics, optional
        Camera; default: ``<path>/intrinsics.json``, else ``camera-intrinsics.txt`` (3x3, depth in
        millimetres), else :data:`SEVEN_SCENES_INTRINSICS` with a warning naming it.
    frames : slice, optional
        Use only these frames (e.g. ``slice(0, 500)``; indices of the sorted frame files). Only
        their files are read (poses, the depth-scale check).
    labels : path, optional
        A labels folder ``000000.png ...`` indexed like the frames used.
    check_units : bool
        Check the depth scale (:func:`~semmatch.io.reading_checks.check_depth_scale`) and every
        frame's median depth.

    Attributes
    ----------
    timestamps : float64 (N,)
        Frame numbers (7-Scenes has no times).
    poses : float64 (N,4,4) or None
        ``T_world_camera`` per frame (NaN rows where unknown); None when no frame has a pose file.

    Raises
    ------
    ValueError
        No frames, a depth image without its colour image, unreadable pose or camera files, a
        pose beyond 10 km or not rigid (the file named), or a depth scale that contradicts the
        depth statistics.
    """

    def __init__(self, path: PathLike, intrinsics: Intrinsics | None = None, *, frames: slice | None = None,
                 labels: PathLike | None = None, check_units: bool = True) -> None:
        self.path = Path(path)
        if not self.path.is_dir():
            raise FileNotFoundError(f"{self.path}: no such 7-Scenes folder")
        depth = sorted(self.path.glob("frame-*.depth.png"))
        if frames is not None:
            depth = depth[frames]
        if not depth:
            raise ValueError(f"{self.path}: no 7-Scenes frames (frame-XXXXXX.depth.png)"
                             + (f" in {frames}" if frames is not None else ""))
        self._depth, self._rgb = depth, []
        for d in depth:
            stem = d.name[: -len(".depth.png")]
            rgb = next((self.path / f"{stem}.color.{ext}" for ext in ("png", "jpg", "jpeg")
                        if (self.path / f"{stem}.color.{ext}").is_file()), None)
            if rgb is None:
                raise ValueError(f"{d}: no colour image {stem}.color.png/.jpg beside it")
            self._rgb.append(rgb)
        self.timestamps = np.array([float(d.name[len("frame-"): -len(".depth.png")]) if
                                    d.name[len("frame-"): -len(".depth.png")].isdigit() else k
                                    for k, d in enumerate(depth)], dtype=np.float64)
        cam = self.path / "camera-intrinsics.txt"
        if intrinsics is None and not (self.path / "intrinsics.json").is_file() and cam.is_file():
            h, w = read_image(depth[0]).shape[:2]
            intrinsics = _read_camera_matrix(cam, w, h, SEVEN_SCENES_INTRINSICS.depth_scale)
        self.intrinsics = self._camera(intrinsics, SEVEN_SCENES_INTRINSICS,
                                       "Microsoft 7-Scenes Kinect (no camera-intrinsics.txt either)")
        poses = np.stack([_read_pose_txt(self.path / f"{d.name[: -len('.depth.png')]}.pose.txt") for d in depth])
        self.poses = poses if np.isfinite(poses).any() else None
        self.labels_dir = Path(labels) if labels is not None else None
        self.check_units = check_units
        if check_units:
            check_depth_scale(self._depth, self.intrinsics.depth_scale, where=str(self.path))
