"""Validation of lower-view frames and their 3D points (shared by every method)."""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache

import cv2
import numpy as np

from ..io import Frame, check_depth, check_intrinsics, check_rgb
from ..io.geometry import Intrinsics, check_pose

__all__ = ["FrameData", "check_frame"]


@dataclass
class FrameData:
    """A validated frame: RGB, depth with invalid values zeroed, pose, intrinsics.

    Attributes
    ----------
    rgb : uint8 (H,W,3)
    depth : float32 (H,W), 0 = no measurement
    valid : bool (H,W)
    pose : float64 (4,4)
    intrinsics : Intrinsics
    name : str
        How messages name the frame.
    """

    rgb: np.ndarray
    depth: np.ndarray
    valid: np.ndarray
    pose: np.ndarray
    intrinsics: Intrinsics
    name: str
    _points: tuple | None = field(default=None, repr=False)

    @property
    def shape(self) -> tuple[int, int]:
        """``(H, W)``."""
        return self.intrinsics.shape

    @property
    def n_valid(self) -> int:
        """Pixels with a depth measurement."""
        return int(np.count_nonzero(self.valid))

    def points(self, stride: int = 1) -> tuple[np.ndarray, np.ndarray]:
        """World points of the valid pixels and their flat pixel indices (raster order).

        Parameters
        ----------
        stride : int
            Keep every ``stride``-th valid pixel (raster order), the paper's "every 4th point".

        Returns
        -------
        points : float32 (N,3)
        pixels : int64 (N,)
        """
        if self._points is None:
            self._points = (np.flatnonzero(self.valid),)
        pix = self._points[0][:: int(stride)]
        return self.world_points(pix), pix

    def world_points(self, pixels: np.ndarray) -> np.ndarray:
        """World coordinates of the given flat pixel indices (float32 (N,3))."""
        intr = self.intrinsics
        uf, vf = _pixel_grid(intr.width, intr.height)
        pixels = np.asarray(pixels, dtype=np.int64)
        z = self.depth.reshape(-1)[pixels]
        cam = np.empty((len(z), 1, 3), np.float32)
        cam[:, 0, 0] = (uf[pixels] - np.float32(intr.cx)) * (z / np.float32(intr.fx))
        cam[:, 0, 1] = (vf[pixels] - np.float32(intr.cy)) * (z / np.float32(intr.fy))
        cam[:, 0, 2] = z
        if len(z) == 0:
            return cam.reshape(0, 3)
        return cv2.transform(cam, self.pose[:3].astype(np.float32)).reshape(-1, 3)


@lru_cache(maxsize=8)
def _pixel_grid(width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """Column and row of every flat pixel index, as float32 (read-only, cached per size)."""
    v, u = np.divmod(np.arange(width * height, dtype=np.int64), width)
    uf, vf = u.astype(np.float32), v.astype(np.float32)
    uf.flags.writeable = False
    vf.flags.writeable = False
    return uf, vf


def check_frame(frame: Frame, *, need_rgb: bool = True) -> FrameData:
    """Validate a :class:`~semmatch.io.Frame` for label transfer (the frame contract of
    :mod:`semmatch.io.contract`, and a pose).

    Parameters
    ----------
    frame : Frame
    need_rgb : bool
        Whether the method reads the RGB image.

    Raises
    ------
    ValueError
        Missing pose, pose with NaN or a non-rotation block, image sizes that do not match the
        intrinsics, RGB that is not ``uint8 (H,W,3)``, depth that is not float or whose median
        is not plausible in metres (:func:`semmatch.io.check_depth_units`).
    TypeError
        ``frame`` is not a Frame-like object.
    """
    name = f"frame {getattr(frame, 'index', '?')}"
    for attr in ("depth", "pose", "intrinsics"):
        if not hasattr(frame, attr):
            raise TypeError(f"{name}: expected a semmatch.io.Frame, got {type(frame).__name__}")
    intr = check_intrinsics(frame.intrinsics, where=name)
    if frame.pose is None:
        raise ValueError(f"{name}: the frame has no pose; label transfer needs T_world_camera")
    pose = check_pose(frame.pose, what=f"{name} pose")
    depth = check_depth(frame.depth, intr.shape, where=name)  # 0 = no measurement
    rgb = frame.rgb
    if need_rgb or rgb is not None:
        rgb = check_rgb(rgb, intr.shape, where=name)
    return FrameData(rgb, depth, depth > 0, pose, intr, name)
