"""Validation of lower-view frames and their 3D points (shared by every method)."""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache

import cv2
import numpy as np

from ..geometry import Intrinsics, check_pose
from ..io import Frame

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
    """Validate a :class:`~semmatch.io.Frame` for label transfer.

    Parameters
    ----------
    frame : Frame
    need_rgb : bool
        Whether the method reads the RGB image.

    Raises
    ------
    ValueError
        Missing pose, pose with NaN or a non-rotation block, image sizes that do not match the
        intrinsics, RGB that is not ``uint8 (H,W,3)``, depth whose median is not plausible in
        metres (:func:`semmatch.io.check_depth_units`).
    TypeError
        ``frame`` is not a Frame-like object.
    """
    name = f"frame {getattr(frame, 'index', '?')}"
    for attr in ("depth", "pose", "intrinsics"):
        if not hasattr(frame, attr):
            raise TypeError(f"{name}: expected a semmatch.io.Frame, got {type(frame).__name__}")
    intr = frame.intrinsics
    if not isinstance(intr, Intrinsics):
        raise ValueError(f"{name}: intrinsics must be a semmatch.geometry.Intrinsics")
    if frame.pose is None:
        raise ValueError(f"{name}: the frame has no pose; label transfer needs T_world_camera")
    pose = check_pose(frame.pose, what=f"{name} pose")
    depth = np.asarray(frame.depth)
    if depth.shape != intr.shape:
        raise ValueError(
            f"{name}: depth is {depth.shape[1::-1] if depth.ndim >= 2 else depth.shape} (WxH) but the "
            f"intrinsics say {intr.width}x{intr.height}"
        )
    if not np.issubdtype(depth.dtype, np.floating):
        raise ValueError(f"{name}: depth must be float metres, got {depth.dtype}")
    depth = depth.astype(np.float32, copy=False)
    from ..io import check_depth_units

    check_depth_units(depth, where=name)  # millimetres read as metres would silently find no support
    valid = depth > 0  # NaN compares False
    if np.isinf(depth).any():
        valid &= np.isfinite(depth)
    if not (valid | (depth == 0)).all():
        depth = np.where(valid, depth, 0).astype(np.float32)
    rgb = frame.rgb
    if need_rgb or rgb is not None:
        rgb = np.asarray(rgb) if rgb is not None else None
        if rgb is None or rgb.shape != intr.shape + (3,) or rgb.dtype != np.uint8:
            got = "nothing" if rgb is None else f"{rgb.dtype} {rgb.shape}"
            raise ValueError(f"{name}: RGB must be uint8 {intr.shape + (3,)} to match the intrinsics, got {got}")
    return FrameData(rgb, depth, valid, pose, intr, name)
