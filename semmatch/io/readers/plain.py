"""Plain RGB-D folders: ``rgb/`` (or ``color/``) and ``depth/`` images paired by sorted file name,
``intrinsics.json`` (or ``--intrinsics``), optional ``poses.txt`` (TUM format, one line per frame)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..geometry import Intrinsics
from ..reading_checks import check_depth_scale
from ..sequences import read_intrinsics, read_tum
from .base import ImageSequence

__all__ = ["is_plain_folder", "PlainFolderSequence"]

PathLike = str | os.PathLike


def _colour_dir(path: Path) -> Path | None:
    return next((path / n for n in ("rgb", "color") if (path / n).is_dir()), None)


def is_plain_folder(path: PathLike) -> bool:
    """True when ``path`` is a folder with ``rgb/`` (or ``color/``) and ``depth/``."""
    p = Path(path)
    return _colour_dir(p) is not None and (p / "depth").is_dir()


class PlainFolderSequence(ImageSequence):
    """Lazy, random-access plain folder: ``rgb/`` (or ``color/``) and ``depth/`` images, ``intrinsics.json``.

    Images pair by sorted file name (the two folders must hold as many); ``poses.txt`` (TUM
    format, one line per frame) is optional.

    Parameters
    ----------
    path : path
    intrinsics : Intrinsics, optional
        The camera, instead of ``<path>/intrinsics.json``.
    frames : slice, optional
        Use only these frames (indices of the sorted images).
    labels : path, optional
        A labels folder ``000000.png ...`` indexed like the frames used.
    check_units : bool
        Check the depth scale (:func:`~semmatch.io.reading_checks.check_depth_scale`) and every
        frame's median depth.

    Raises
    ------
    ValueError
        No camera (neither ``intrinsics`` nor ``intrinsics.json``: none is assumed for a folder
        that names none), no colour or depth folder, different numbers of images, a ``poses.txt``
        of another length.
    """

    def __init__(self, path: PathLike, intrinsics: Intrinsics | None = None, *, frames: slice | None = None,
                 labels: PathLike | None = None, check_units: bool = True) -> None:
        self.path = Path(path)
        if not self.path.is_dir():
            raise FileNotFoundError(f"{self.path}: no such folder")
        colour = _colour_dir(self.path)
        if colour is None or not (self.path / "depth").is_dir():
            raise ValueError(f"{self.path}: not a plain RGB-D folder (needs rgb/ or color/, and depth/)")
        if intrinsics is None and not (self.path / "intrinsics.json").is_file():
            raise ValueError(f"{self.path}: no intrinsics.json; a plain folder names no camera, so none is assumed "
                             "(write width, height, fx, fy, cx, cy and depth_scale into intrinsics.json, or pass "
                             "--intrinsics FILE.json)")
        self.intrinsics = intrinsics if intrinsics is not None else read_intrinsics(self.path / "intrinsics.json")
        exts = (".png", ".jpg", ".jpeg")
        self._rgb = sorted(p for p in colour.iterdir() if p.suffix.lower() in exts)
        self._depth = sorted(p for p in (self.path / "depth").iterdir() if p.suffix.lower() == ".png")
        if not self._depth or len(self._rgb) != len(self._depth):
            raise ValueError(f"{self.path}: {len(self._rgb)} colour and {len(self._depth)} depth images; "
                             "they must pair one to one (sorted by name)")
        self.timestamps = np.arange(len(self._depth), dtype=np.float64)
        self.poses = None
        if (self.path / "poses.txt").is_file():
            self.timestamps, self.poses = read_tum(self.path / "poses.txt")
            if len(self.poses) != len(self._depth):
                raise ValueError(f"{self.path / 'poses.txt'}: {len(self.poses)} poses for {len(self._depth)} frames")
        if frames is not None:
            keep = range(len(self._depth))[frames]
            if not len(keep):
                raise ValueError(f"{self.path}: no frame in {frames} ({len(self._depth)} frames)")
            self._rgb, self._depth = [self._rgb[i] for i in keep], [self._depth[i] for i in keep]
            self.timestamps = self.timestamps[list(keep)]
            self.poses = None if self.poses is None else self.poses[list(keep)]
        self.labels_dir = Path(labels) if labels is not None else None
        self.check_units = check_units
        if check_units:
            check_depth_scale(self._depth, self.intrinsics.depth_scale, where=str(self.path))
