"""What the recording readers share: the lazy image sequence, and views of a sequence (a frame range, other poses).

:class:`ImageSequence` is the random-access sequence over lists of colour and depth files that
the TUM RGB-D, 7-Scenes and plain-folder readers fill in; :class:`SequenceView` shows any reader's
sequence through a frame range and/or with other poses (``--frames``, ``--estimate-poses``), with
the reader's other attributes (``path``, ``intrinsics``, ``read_labels`` ...) passed through.
"""

from __future__ import annotations

import dataclasses
import os
import warnings
from collections.abc import Iterator
from collections.abc import Sequence as _SequenceABC
from pathlib import Path
from typing import Any

import numpy as np

from ..geometry import Intrinsics
from ..images import check_depth_units, read_label_image, read_rgb
from ..reading_checks import check_label_ids, read_raw_depth
from ..sequences import Frame, frame_index, read_intrinsics

__all__ = ["ImageSequence", "SequenceView", "frame_files", "missing_poses"]

PathLike = str | os.PathLike


class ImageSequence(_SequenceABC):
    """Lazy, random-access sequence over lists of colour and depth files (the readers' shared part).

    Subclasses set ``path``, ``_rgb``, ``_depth`` (paths), ``intrinsics``, ``timestamps``,
    ``poses`` ((N,4,4) with NaN rows, or None), ``labels_dir`` and ``check_units``.
    """

    path: Path
    _rgb: list[Path]
    _depth: list[Path]
    intrinsics: Intrinsics
    timestamps: np.ndarray
    poses: np.ndarray | None
    labels_dir: Path | None
    check_units: bool

    def __len__(self) -> int:
        return len(self._rgb)

    @property
    def has_poses(self) -> bool:
        """True when every frame has a ground-truth pose."""
        return self.poses is not None and bool(np.isfinite(self.poses).all())

    def frame_files(self, i: int) -> tuple[Path, ...]:
        """The files frame ``i`` is read from (colour, depth): what a cache of results keys on."""
        i = frame_index(i, len(self))
        return self._rgb[i], self._depth[i]

    def _camera(self, intrinsics: Intrinsics | None, assumed: Intrinsics, camera: str) -> Intrinsics:
        """``intrinsics``, else ``<path>/intrinsics.json``, else ``assumed`` with a warning naming ``camera``."""
        if intrinsics is not None:
            return intrinsics
        if (self.path / "intrinsics.json").is_file():
            return read_intrinsics(self.path / "intrinsics.json")
        warnings.warn(
            f"{self.path}: no intrinsics.json; ASSUMING the {camera} (fx {assumed.fx:g}, fy {assumed.fy:g}, "
            f"cx {assumed.cx:g}, cy {assumed.cy:g}, depth_scale {assumed.depth_scale:g} per metre). If the "
            "recording comes from another camera, write its intrinsics.json into the folder (or pass --intrinsics)",
            UserWarning, stacklevel=3)
        return assumed

    def _read_images(self, i: int) -> tuple[np.ndarray, np.ndarray, str, str]:
        """Frame ``i``'s colour (uint8 RGB) and depth (float32 metres), and where each came from (for messages)."""
        rp, dp = self._rgb[i], self._depth[i]
        # 16-bit colour scaled, not wrapped to its low byte
        return read_rgb(rp), read_raw_depth(dp, self.intrinsics.depth_scale), str(rp), str(dp)

    def __getitem__(self, i):  # type: ignore[override]
        if isinstance(i, slice):
            return [self[j] for j in range(*i.indices(len(self)))]
        i = frame_index(i, len(self))
        rgb, depth, rp, dp = self._read_images(i)
        shape = self.intrinsics.shape
        for p, arr in ((rp, rgb), (dp, depth)):
            if arr.shape[:2] != shape:
                raise ValueError(
                    f"{p}: frame {i} is {arr.shape[1]}x{arr.shape[0]}, the intrinsics say "
                    f"{self.intrinsics.width}x{self.intrinsics.height}"
                )
        if self.check_units:
            check_depth_units(depth, where=f"{dp} (depth_scale {self.intrinsics.depth_scale:g})")
        labels = None
        if self.labels_dir is not None:
            lp = self.labels_dir / f"{i:06d}.png"
            if not lp.is_file():
                raise ValueError(f"{self.labels_dir}: frame {i} ({lp.name}) is missing")
            labels = check_label_ids(read_label_image(lp), where=lp)
            if labels.shape != shape:
                raise ValueError(f"{lp}: labels are {labels.shape}, expected {shape}")
        pose = None
        if self.poses is not None and np.isfinite(self.poses[i]).all():
            pose = self.poses[i].copy()
        return Frame(rgb, depth, labels, pose, self.intrinsics, index=i, timestamp=float(self.timestamps[i]))

    def __iter__(self) -> Iterator[Frame]:
        for i in range(len(self)):
            yield self[i]

    def __repr__(self) -> str:
        return f"{type(self).__name__}({str(self.path)!r}, frames={len(self)})"


class SequenceView(_SequenceABC):
    """A recording seen through a frame range and/or with other poses; everything else is the recording's.

    Frame ``i`` of the view is frame ``indices[i]`` of ``base`` (its ``index`` renumbered to
    ``i``), with pose ``poses[i]`` when ``poses`` is given. ``read_labels(i)`` and
    ``read_instances(i)`` map ``i`` the same way; other attributes (``path``, ``intrinsics``,
    ``labels_dir``, ``has_labels`` ...) are the recording's.

    Parameters
    ----------
    base : sequence of Frame
        A reader (``len``, ``[i]``, ``intrinsics``, ``timestamps``, ``poses``).
    indices : sequence of int, optional
        Frames of ``base`` to show (default all).
    poses : ndarray (N, 4, 4), optional
        ``T_world_camera`` per frame of the view, replacing the recording's (NaN rows: unknown).
    """

    def __init__(self, base, indices: _SequenceABC[int] | None = None, poses: np.ndarray | None = None) -> None:
        self.base = base
        self.indices = range(len(base)) if indices is None else indices
        ts = getattr(base, "timestamps", None)
        self.timestamps = (np.asarray(ts, dtype=np.float64)[list(self.indices)] if ts is not None
                           else np.arange(len(self.indices), dtype=np.float64))
        if poses is not None:
            poses = np.asarray(poses, dtype=np.float64)
            if poses.shape != (len(self.indices), 4, 4):
                raise ValueError(f"{getattr(base, 'path', 'sequence')}: {len(poses)} poses for "
                                 f"{len(self.indices)} frames")
            self.poses: np.ndarray | None = poses
        else:
            bp = getattr(base, "poses", None)
            self.poses = None if bp is None else np.asarray(bp, dtype=np.float64)[list(self.indices)]

    def __getattr__(self, name: str) -> Any:
        if name == "base":  # not set yet (unpickling): no recursion
            raise AttributeError(name)
        return getattr(self.base, name)

    def __len__(self) -> int:
        return len(self.indices)

    @property
    def has_poses(self) -> bool:
        """True when every frame of the view has a pose."""
        return self.poses is not None and bool(np.isfinite(self.poses).all())

    def __getitem__(self, i):  # type: ignore[override]
        if isinstance(i, slice):
            return [self[j] for j in range(*i.indices(len(self)))]
        i = frame_index(i, len(self))
        f = self.base[self.indices[i]]
        pose = f.pose
        if self.poses is not None:
            pose = self.poses[i].copy() if np.isfinite(self.poses[i]).all() else None
        return dataclasses.replace(f, pose=pose, index=i, timestamp=float(self.timestamps[i]))

    def __iter__(self) -> Iterator[Frame]:
        for i in range(len(self)):
            yield self[i]

    def read_labels(self, i: int) -> np.ndarray | None:
        """Label image of frame ``i`` of the view (the recording's reader decides)."""
        return self.base.read_labels(self.indices[frame_index(i, len(self))])

    def read_instances(self, i: int) -> np.ndarray:
        """Instance image of frame ``i`` of the view (the recording's reader decides)."""
        return self.base.read_instances(self.indices[frame_index(i, len(self))])

    def frame_files(self, i: int) -> tuple[Path, ...]:
        """The files frame ``i`` of the view is read from (see :func:`frame_files`)."""
        return frame_files(self.base, self.indices[frame_index(i, len(self))])

    def __repr__(self) -> str:
        return f"SequenceView({self.base!r}, frames={len(self)})"


def frame_files(seq, i: int) -> tuple[Path, ...]:
    """The files frame ``i`` of a sequence is read from, or ``()`` when its reader does not say.

    Readers name them with a ``frame_files(i)`` method; a sequence folder
    (:class:`~semmatch.io.SequenceReader`) has ``rgb/NNNNNN.png`` and ``depth/NNNNNN.png``.

    Parameters
    ----------
    seq : sequence of Frame
    i : int

    Returns
    -------
    tuple of Path
    """
    if hasattr(seq, "frame_files"):
        return tuple(seq.frame_files(i))
    path = getattr(seq, "path", None)
    if path is not None and (Path(path) / "rgb" / f"{i:06d}.png").is_file():
        return Path(path) / "rgb" / f"{i:06d}.png", Path(path) / "depth" / f"{i:06d}.png"
    return ()


def missing_poses(seq) -> str | None:
    """Why the frames of ``seq`` cannot be placed at their recorded poses (None: every frame has one).

    Parameters
    ----------
    seq : sequence of Frame
        A reader with ``poses`` ((N, 4, 4) with NaN rows where unknown, or None).

    Returns
    -------
    str or None
        E.g. ``"has no recorded poses"`` or ``"has no recorded pose for 3 of 10 frames (first: frame 4)"``.
    """
    poses = getattr(seq, "poses", None)
    if poses is None:
        return "has no recorded poses"
    bad = np.flatnonzero(~np.isfinite(np.asarray(poses, dtype=np.float64)).all(axis=(1, 2)))
    if len(bad):
        return f"has no recorded pose for {len(bad)} of {len(seq)} frames (first: frame {bad[0]})"
    return None
