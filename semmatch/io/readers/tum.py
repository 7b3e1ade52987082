"""TUM RGB-D folders (https://cvg.cit.tum.de/data/datasets/rgbd-dataset/file_formats)::

    <folder>/rgb.txt            "timestamp filename" per line, '#' comments
    <folder>/depth.txt          the same for 16-bit depth PNGs (value / 5000 = metres)
    <folder>/groundtruth.txt    optional: "timestamp tx ty tz qx qy qz qw" (T_world_camera)
    <folder>/intrinsics.json    optional: our intrinsics file (wins over the defaults)

Colour and depth images are associated by timestamp as TUM's ``associate.py`` does; ground-truth
poses are interpolated at the colour timestamps (:mod:`semmatch.io.timestamps`).
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np

from ..geometry import Intrinsics
from ..reading_checks import check_depth_scale
from ..sequences import listed_file, read_tum
from ..timestamps import associate_frames, interpolate_poses, read_file_list
from .base import ImageSequence

__all__ = ["TUM_INTRINSICS", "tum_camera", "is_tum_rgbd", "TumRgbdSequence", "read_tum_rgbd", "write_tum_rgbd"]

PathLike = str | os.PathLike

#: published calibrations of the TUM RGB-D cameras (depth registered to colour), 640x480
TUM_INTRINSICS: dict[str, Intrinsics] = {
    "freiburg1": Intrinsics(640, 480, 517.3, 516.5, 318.6, 255.3, 5000.0),
    "freiburg2": Intrinsics(640, 480, 520.9, 521.0, 325.1, 249.7, 5000.0),
    "freiburg3": Intrinsics(640, 480, 535.4, 539.2, 320.1, 247.6, 5000.0),
    "default": Intrinsics(640, 480, 525.0, 525.0, 319.5, 239.5, 5000.0),
}


def tum_camera(name: str) -> str | None:
    """The TUM camera (``freiburg1/2/3``) a folder name selects, also by short name (``fr1_desk``).

    Parameters
    ----------
    name : str
        A folder name such as ``rgbd_dataset_freiburg1_desk`` or ``fr2_xyz``.

    Returns
    -------
    str or None
        A key of :data:`TUM_INTRINSICS`, or None when the name names no TUM camera.
    """
    m = re.search(r"(?:freiburg|(?<![a-z])fr)([123])(?![0-9])", name.lower())
    return f"freiburg{m.group(1)}" if m else None


def is_tum_rgbd(path: PathLike) -> bool:
    """True when ``path`` is a folder with ``rgb.txt`` and ``depth.txt``."""
    p = Path(path)
    return (p / "rgb.txt").is_file() and (p / "depth.txt").is_file()


class TumRgbdSequence(ImageSequence):
    """Lazy, random-access TUM RGB-D sequence: ``len(seq)``, ``seq[i] -> Frame``.

    Parameters
    ----------
    path : path
        The TUM folder.
    intrinsics : Intrinsics, optional
        Camera; default: ``<path>/intrinsics.json`` when present, else the published TUM
        calibration of the camera the folder name names (``freiburg1/2/3`` or ``fr1/2/3``, e.g.
        ``fr1_desk``; :func:`tum_camera`), else TUM's default camera; an assumed camera is
        named in a warning.
    max_difference : float
        Association window (seconds) for colour/depth pairs (TUM default 0.02).
    max_unmatched : float
        Fraction of colour frames allowed to have no depth partner; they are dropped with a
        warning. More than that is an error.
    max_gt_gap : float
        Longest ground-truth gap (seconds) bridged by pose interpolation.
    frames : slice, optional
        Use only these associated frames (e.g. ``slice(0, 250)``).
    labels : path, optional
        A labels folder ``000000.png ...`` indexed like the frames used.
    check_units : bool
        Check the depth scale against the depth statistics when the recording is opened
        (:func:`~semmatch.io.reading_checks.check_depth_scale`) and the median depth of every
        frame read (:func:`semmatch.io.check_depth_units`).

    Attributes
    ----------
    timestamps : float64 (N,)
        Colour timestamps of the associated frames.
    poses : float64 (N,4,4) or None
        Ground-truth ``T_world_camera`` per frame (NaN rows where none); None without
        ``groundtruth.txt``.

    Raises
    ------
    ValueError
        Unreadable list files, no colour/depth pair within ``max_difference`` (the message gives
        both time ranges), too many unmatched frames, a ground truth that covers no frame, or
        a depth scale that contradicts the depth statistics.

    Warns
    -----
    UserWarning
        No intrinsics given or in the folder: the message names the camera assumed.
    """

    def __init__(
        self,
        path: PathLike,
        intrinsics: Intrinsics | None = None,
        *,
        max_difference: float = 0.02,
        max_unmatched: float = 0.05,
        max_gt_gap: float = 0.1,
        frames: slice | None = None,
        labels: PathLike | None = None,
        check_units: bool = True,
    ) -> None:
        self.path = Path(path)
        if not self.path.is_dir():
            raise FileNotFoundError(f"{self.path}: no such TUM RGB-D folder")
        for name in ("rgb.txt", "depth.txt"):
            if not (self.path / name).is_file():
                raise ValueError(f"{self.path}: not a TUM RGB-D folder (no {name})")
        pairs, (t_rgb, f_rgb), (t_dep, f_dep) = self._associate(max_difference, max_unmatched)
        if frames is not None:
            pairs = pairs[frames]
            if not len(pairs):
                raise ValueError(f"{self.path}: no associated frame in {frames}")
        self.timestamps = t_rgb[pairs[:, 0]]
        self.depth_timestamps = t_dep[pairs[:, 1]]
        # entries stay inside the folder (no absolute paths, no '..'): semmatch.io.listed_file
        self._rgb = [listed_file(self.path, f_rgb[i], str(self.path / "rgb.txt")) for i in pairs[:, 0]]
        self._depth = [listed_file(self.path, f_dep[j], str(self.path / "depth.txt")) for j in pairs[:, 1]]
        key = tum_camera(self.path.resolve().name) or "default"
        self.intrinsics = self._camera(intrinsics, TUM_INTRINSICS[key],
                                       f"TUM {key} camera" + ("" if key != "default" else
                                                              " (the folder name names no freiburg1/2/3 camera)"))
        self.labels_dir = Path(labels) if labels is not None else None
        self.check_units = check_units
        if check_units:
            check_depth_scale(self._depth, self.intrinsics.depth_scale, where=str(self.path))
        self.poses: np.ndarray | None = None
        gt = self.path / "groundtruth.txt"
        if gt.is_file():
            gt_t, gt_p = read_tum(gt)
            self.poses = interpolate_poses(self.timestamps, gt_t, gt_p, max_gt_gap)
            n_pose = int(np.isfinite(self.poses[:, 0, 0]).sum())
            if n_pose == 0:
                raise ValueError(
                    f"{gt}: ground truth ({gt_t.min():.3f}..{gt_t.max():.3f}) covers none of the "
                    f"{len(self)} frames ({self.timestamps[0]:.3f}..{self.timestamps[-1]:.3f})"
                )

    def _associate(self, max_difference: float, max_unmatched: float):
        """The colour/depth pairs (K, 2) and both lists (times, files); unmatched colour frames warned or refused."""
        rgb_txt, dep_txt = self.path / "rgb.txt", self.path / "depth.txt"
        t_rgb, f_rgb = read_file_list(rgb_txt)
        t_dep, f_dep = read_file_list(dep_txt)
        pairs = associate_frames(t_rgb, t_dep, max_difference, max_unmatched, rgb_where=str(rgb_txt),
                                 depth_where=str(dep_txt))
        return pairs, (t_rgb, f_rgb), (t_dep, f_dep)


def read_tum_rgbd(path: PathLike, intrinsics: Intrinsics | None = None, **kwargs) -> TumRgbdSequence:
    """Open a TUM RGB-D folder as a sequence (see :class:`TumRgbdSequence`)."""
    return TumRgbdSequence(path, intrinsics, **kwargs)


def write_tum_rgbd(path: PathLike, frames, intrinsics: Intrinsics, *, fps: float | None = None,
                   overwrite: bool = False, inputs=()) -> Path:
    """Write frames as a TUM RGB-D folder (the layout :class:`TumRgbdSequence` reads), atomically.

    ``rgb/<t>.png``, ``depth/<t>.png`` (16 bit, value / 5000 = metres), ``rgb.txt``,
    ``depth.txt``, ``groundtruth.txt`` (the frames' poses, when any frame has one) and
    ``intrinsics.json`` (the camera, depth scale 5000). The folder is filled under a temporary
    name and renamed when complete (:func:`semmatch.io.files.output_dir_writer`).

    Parameters
    ----------
    path : path
        The new folder.
    frames : iterable of Frame
    intrinsics : Intrinsics
    fps : float, optional
        Stamp frame ``i`` at ``i / fps`` seconds instead of its own timestamp (a simulated
        sequence's timestamps are frame numbers, 1 Hz: too sparse for TUM's pose interpolation,
        which leaves frames more than 0.1 s from a pose sample without one).
    overwrite : bool
        Replace a folder semmatch wrote (anything else is refused).
    inputs : sequence of paths
        The recording read (the output may not be, lie inside or contain it).

    Returns
    -------
    Path

    Raises
    ------
    ValueError
        No frames, a non-positive ``fps``, or timestamps that do not increase.
    """
    import dataclasses

    from ..files import output_dir_writer
    from ..images import write_depth, write_image
    from ..sequences import write_intrinsics, write_tum

    if fps is not None and not fps > 0:
        raise ValueError(f"fps must be > 0, got {fps}")
    with output_dir_writer(path, "tum-rgbd", overwrite=overwrite, inputs=inputs) as tmp:
        lines = {"rgb": ["# color images", "# timestamp filename"], "depth": ["# depth maps", "# timestamp filename"]}
        stamps, poses = [], []
        for i, f in enumerate(frames):
            t = i / fps if fps is not None else float(f.timestamp if f.timestamp is not None else i)
            if stamps and t <= stamps[-1]:
                raise ValueError(f"{path}: frame {i}'s timestamp {t:.6f} does not follow {stamps[-1]:.6f} "
                                 "(pass fps to stamp the frames anew)")
            stamps.append(t)
            for kind in ("rgb", "depth"):
                name = f"{kind}/{t:.6f}.png"
                (tmp / kind).mkdir(exist_ok=True)
                if kind == "rgb":
                    write_image(tmp / name, f.rgb)
                else:
                    write_depth(tmp / name, f.depth, 5000.0)
                lines[kind].append(f"{t:.6f} {name}")
            if f.pose is not None:
                poses.append((t, f.pose))
        if not stamps:
            raise ValueError(f"{path}: no frames to write")
        for kind, text in lines.items():
            (tmp / f"{kind}.txt").write_text("\n".join(text) + "\n")
        write_intrinsics(tmp / "intrinsics.json", dataclasses.replace(intrinsics, depth_scale=5000.0))
        if poses:
            write_tum(tmp / "groundtruth.txt", np.array([t for t, _ in poses]), np.stack([T for _, T in poses]))
    return Path(path)
