"""Real recordings: TUM RGB-D, 7-Scenes and plain image folders as sequences of :class:`semmatch.io.Frame`.

Every reader is lazy and random access (``len(seq)``, ``seq[i] -> Frame``); :func:`read_recording`
picks the reader from the folder's layout. No camera is assumed silently: a folder without its
calibration gets the published calibration of the camera its layout names, with a warning that
names it, and a depth scale that contradicts the depth statistics (millimetre PNGs read as TUM's
1/5000 m, which shrinks the room five times) is refused (:func:`check_depth_scale`). 16-bit depth
value 65535 (and 0) is "no measurement". Ground-truth poses are NaN where a frame has none.

A TUM RGB-D folder (https://cvg.cit.tum.de/data/datasets/rgbd-dataset/file_formats)::

    <folder>/rgb.txt            "timestamp filename" per line, '#' comments
    <folder>/depth.txt          the same for 16-bit depth PNGs (value / 5000 = metres)
    <folder>/groundtruth.txt    optional: "timestamp tx ty tz qx qy qz qw" (T_world_camera)
    <folder>/intrinsics.json    optional: our intrinsics file (wins over the defaults)

A 7-Scenes folder (Microsoft 7-Scenes; also the layout of andyzeng/tsdf-fusion-python's data)::

    <folder>/frame-000000.color.png|jpg   colour
    <folder>/frame-000000.depth.png       16-bit depth in millimetres (65535 = no measurement)
    <folder>/frame-000000.pose.txt        optional: 4x4 T_world_camera (inf/NaN = unknown)
    <folder>/camera-intrinsics.txt        optional: the 3x3 camera matrix
    <folder>/intrinsics.json              optional: our intrinsics file (wins over both)

A plain folder: ``rgb/`` (or ``color/``) and ``depth/`` images paired by sorted file name,
``intrinsics.json`` required, optional ``poses.txt`` (TUM format, one line per frame).

Colour and depth images are associated by timestamp as TUM's ``associate.py`` does (greedy,
closest pairs first, each image used once, ``|dt| <= max_difference``); ground-truth poses are
interpolated at the colour timestamps (linear translation, slerp rotation) when the frame lies
between two ground-truth samples at most ``max_gt_gap`` apart (:mod:`semmatch.io.timestamps`:
the list files, the association and the interpolation, importable from here too).
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Iterator
from collections.abc import Sequence as _SequenceABC
from pathlib import Path

import numpy as np

from ..geometry import Intrinsics
from .images import check_depth_units, read_image, read_label_image, read_rgb
from .sequences import Frame, frame_index, listed_file, read_intrinsics, read_tum
from .timestamps import associate, associate_frames, interpolate_poses, read_file_list

__all__ = [
    "TUM_INTRINSICS",
    "SEVEN_SCENES_INTRINSICS",
    "TumRgbdSequence",
    "SevenScenesSequence",
    "PlainFolderSequence",
    "is_tum_rgbd",
    "is_7scenes",
    "read_recording",
    "check_depth_scale",
    "tum_camera",
    "read_tum_rgbd",
    "read_file_list",
    "associate",
    "associate_frames",
    "interpolate_poses",
]

PathLike = str | os.PathLike

#: published calibrations of the TUM RGB-D cameras (depth registered to colour), 640x480
TUM_INTRINSICS: dict[str, Intrinsics] = {
    "freiburg1": Intrinsics(640, 480, 517.3, 516.5, 318.6, 255.3, 5000.0),
    "freiburg2": Intrinsics(640, 480, 520.9, 521.0, 325.1, 249.7, 5000.0),
    "freiburg3": Intrinsics(640, 480, 535.4, 539.2, 320.1, 247.6, 5000.0),
    "default": Intrinsics(640, 480, 525.0, 525.0, 319.5, 239.5, 5000.0),
}

#: Microsoft 7-Scenes Kinect (its published camera matrix; depth PNGs in millimetres)
SEVEN_SCENES_INTRINSICS = Intrinsics(640, 480, 585.0, 585.0, 320.0, 240.0, 1000.0)

#: 16-bit depth values that mean "no measurement" (0, and 65535 as 7-Scenes writes its holes)
DEPTH_HOLE = 65535

#: depth scale check (:func:`check_depth_scale`): no RGB-D camera of these recordings measures a
#: scene whose median depth is nearer than this (metres); Kinect v1's range starts at 0.4-0.5 m
NEAREST_MEDIAN_DEPTH = 0.5


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
    import re

    m = re.search(r"(?:freiburg|(?<![a-z])fr)([123])(?![0-9])", name.lower())
    return f"freiburg{m.group(1)}" if m else None


def read_raw_depth(path: PathLike, depth_scale: float) -> np.ndarray:
    """Read a 16-bit depth PNG as float32 metres, with 0 and 65535 as holes (0).

    Raises
    ------
    ValueError
        Not a single-channel 16-bit image (the message names the file).
    """
    raw = read_image(path)
    if raw.ndim != 2 or raw.dtype != np.uint16:
        raise ValueError(f"{path}: depth must be a 16-bit single-channel PNG, got {raw.dtype} {raw.shape}")
    out = raw.astype(np.float32) / np.float32(depth_scale)
    out[raw == DEPTH_HOLE] = 0.0
    return out


def check_depth_scale(depth_paths: _SequenceABC[PathLike], depth_scale: float, *, where: str,
                      samples: int = 5) -> float:
    """Refuse a depth scale that contradicts the depth statistics; return the median depth (m).

    The median valid depth of up to ``samples`` frames spread over the recording, read at
    ``depth_scale``, must not be nearer than :data:`NEAREST_MEDIAN_DEPTH` when the same values
    read as millimetres give a room-sized median (0.5 .. 10 m): that is a millimetre recording
    read at a finer scale (TUM's 5000 makes it five times too small, and everything downstream,
    odometry, fusion, trajectory errors, still looks plausible).

    Parameters
    ----------
    depth_paths : sequence of path
        The recording's depth PNGs.
    depth_scale : float
        The scale the recording would be read with (PNG value per metre).
    where : str
        What the recording is and where its scale came from, for the message.
    samples : int
        Frames inspected.

    Returns
    -------
    float
        Median valid depth in metres at ``depth_scale`` (NaN when the frames have none).

    Raises
    ------
    ValueError
        The contradiction above; the message gives both medians and what to change.
    """
    if not len(depth_paths):
        return float("nan")
    pick = np.unique(np.linspace(0, len(depth_paths) - 1, min(samples, len(depth_paths))).round().astype(int))
    vals = []
    for k in pick:
        d = read_raw_depth(depth_paths[k], 1.0)[::4, ::4]
        vals.append(d[d > 0])
    v = np.concatenate(vals)
    if v.size == 0:
        return float("nan")
    med = float(np.median(v)) / depth_scale
    as_mm = med * depth_scale / 1000.0
    if depth_scale > 1000.0 and med < NEAREST_MEDIAN_DEPTH and 0.5 <= as_mm <= 10.0:
        raise ValueError(
            f"{where}: at depth_scale {depth_scale:g} the median depth of {len(pick)} frames is {med:.2f} m, "
            f"nearer than RGB-D cameras measure; read as millimetres it is {as_mm:.2f} m. The depth PNGs are most "
            f"likely in millimetres: write an intrinsics.json with \"depth_scale\": 1000 (and the camera's fx, fy, "
            f"cx, cy) into the folder; at {depth_scale:g} the map would be {depth_scale / 1000:g}x too small"
        )
    return med


def is_tum_rgbd(path: PathLike) -> bool:
    """True when ``path`` is a folder with ``rgb.txt`` and ``depth.txt``."""
    p = Path(path)
    return (p / "rgb.txt").is_file() and (p / "depth.txt").is_file()


class _ImageSequence(_SequenceABC):
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

    def _camera(self, intrinsics: Intrinsics | None, assumed: Intrinsics, camera: str) -> Intrinsics:
        """``intrinsics``, else ``<path>/intrinsics.json``, else ``assumed`` with a warning naming ``camera``."""
        if intrinsics is not None:
            return intrinsics
        if (self.path / "intrinsics.json").is_file():
            return read_intrinsics(self.path / "intrinsics.json")
        warnings.warn(
            f"{self.path}: no intrinsics.json; ASSUMING the {camera} (fx {assumed.fx:g}, fy {assumed.fy:g}, "
            f"cx {assumed.cx:g}, cy {assumed.cy:g}, depth_scale {assumed.depth_scale:g} per metre). If the "
            "recording comes from another camera, write its intrinsics.json into the folder",
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
            labels = read_label_image(lp)
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


class TumRgbdSequence(_ImageSequence):
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
    labels : path, optional
        A labels folder ``000000.png ...`` indexed like the associated frames.
    check_units : bool
        Check the depth scale against the depth statistics when the recording is opened
        (:func:`check_depth_scale`) and the median depth of every frame read
        (:func:`semmatch.io.check_depth_units`).

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
        labels: PathLike | None = None,
        check_units: bool = True,
    ) -> None:
        self.path = Path(path)
        if not self.path.is_dir():
            raise FileNotFoundError(f"{self.path}: no such TUM RGB-D folder")
        for name in ("rgb.txt", "depth.txt"):
            if not (self.path / name).is_file():
                raise ValueError(f"{self.path}: not a TUM RGB-D folder (no {name})")
        t_rgb, f_rgb = read_file_list(self.path / "rgb.txt")
        t_dep, f_dep = read_file_list(self.path / "depth.txt")
        rgb_txt, dep_txt = self.path / "rgb.txt", self.path / "depth.txt"
        pairs = associate_frames(t_rgb, t_dep, max_difference, max_unmatched, rgb_where=str(rgb_txt),
                                 depth_where=str(dep_txt))
        self.timestamps = t_rgb[pairs[:, 0]]
        self.depth_timestamps = t_dep[pairs[:, 1]]
        # entries stay inside the folder (no absolute paths, no '..'): semmatch.io.listed_file
        self._rgb = [listed_file(self.path, f_rgb[i], str(rgb_txt)) for i in pairs[:, 0]]
        self._depth = [listed_file(self.path, f_dep[j], str(dep_txt)) for j in pairs[:, 1]]
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



def read_tum_rgbd(path: PathLike, intrinsics: Intrinsics | None = None, **kwargs) -> TumRgbdSequence:
    """Open a TUM RGB-D folder as a sequence (see :class:`TumRgbdSequence`)."""
    return TumRgbdSequence(path, intrinsics, **kwargs)


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
    """A 7-Scenes ``frame-*.pose.txt`` (4x4); NaN when it is missing or holds inf/NaN (unknown pose)."""
    if not path.is_file():
        return np.full((4, 4), np.nan)
    T = _read_matrix(path, 4, "4x4 pose")
    return T if np.isfinite(T).all() else np.full((4, 4), np.nan)


def _read_camera_matrix(path: Path, width: int, height: int, depth_scale: float) -> Intrinsics:
    K = _read_matrix(path, 3, "3x3 camera matrix")
    return Intrinsics(width, height, K[0, 0], K[1, 1], K[0, 2], K[1, 2], depth_scale)


class SevenScenesSequence(_ImageSequence):
    """Lazy, random-access 7-Scenes folder: ``frame-XXXXXX.color.*``, ``.depth.png``, ``.pose.txt``.

    Parameters
    ----------
    path : path
        The folder (one 7-Scenes ``seq-NN`` folder, or andyzeng/tsdf-fusion-python's ``data``).
    intrinsics : Intrinsics, optional
        Camera; default: ``<path>/intrinsics.json``, else ``camera-intrinsics.txt`` (3x3, depth in
        millimetres), else :data:`SEVEN_SCENES_INTRINSICS` with a warning naming it.
    frames : slice, optional
        Use only these frames (e.g. ``slice(0, 500)``; indices of the sorted frame files).
    labels : path, optional
        A labels folder ``000000.png ...`` indexed like the frames used.
    check_units : bool
        Check the depth scale (:func:`check_depth_scale`) and every frame's median depth.

    Attributes
    ----------
    timestamps : float64 (N,)
        Frame numbers (7-Scenes has no times).
    poses : float64 (N,4,4) or None
        ``T_world_camera`` per frame (NaN rows where unknown); None when no frame has a pose file.

    Raises
    ------
    ValueError
        No frames, a depth image without its colour image, unreadable pose or camera files, or a
        depth scale that contradicts the depth statistics.
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


class PlainFolderSequence(_ImageSequence):
    """Lazy, random-access plain folder: ``rgb/`` (or ``color/``) and ``depth/`` images, ``intrinsics.json``.

    Images pair by sorted file name (the two folders must hold as many); ``poses.txt`` (TUM
    format, one line per frame) is optional.

    Parameters
    ----------
    path : path
    labels : path, optional
    check_units : bool
        Check the depth scale (:func:`check_depth_scale`) and every frame's median depth.

    Raises
    ------
    ValueError
        No ``intrinsics.json`` (no camera is assumed for a folder that names none), no colour or
        depth folder, different numbers of images, a ``poses.txt`` of another length.
    """

    def __init__(self, path: PathLike, *, labels: PathLike | None = None, check_units: bool = True) -> None:
        self.path = Path(path)
        if not self.path.is_dir():
            raise FileNotFoundError(f"{self.path}: no such folder")
        colour = next((self.path / n for n in ("rgb", "color") if (self.path / n).is_dir()), None)
        if colour is None or not (self.path / "depth").is_dir():
            raise ValueError(f"{self.path}: not a plain RGB-D folder (needs rgb/ or color/, and depth/)")
        if not (self.path / "intrinsics.json").is_file():
            raise ValueError(f"{self.path}: no intrinsics.json; a plain folder names no camera, so none is assumed "
                             "(write width, height, fx, fy, cx, cy and depth_scale into intrinsics.json)")
        self.intrinsics = read_intrinsics(self.path / "intrinsics.json")
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
        self.labels_dir = Path(labels) if labels is not None else None
        self.check_units = check_units
        if check_units:
            check_depth_scale(self._depth, self.intrinsics.depth_scale, where=str(self.path))


def read_recording(path: PathLike, **kwargs):
    """Open any supported recording folder, choosing the reader from its layout.

    7-Scenes (``frame-*.depth.png``): :class:`SevenScenesSequence`; TUM RGB-D (``rgb.txt``,
    ``depth.txt``): :class:`TumRgbdSequence`; a semmatch sequence folder (``intrinsics.json``
    and ``poses.txt``): :func:`semmatch.io.read_sequence`; ``rgb/`` + ``depth/``:
    :class:`PlainFolderSequence`.

    Parameters
    ----------
    path : path
    **kwargs
        Passed to the reader (e.g. ``labels``).

    Raises
    ------
    ValueError
        A folder of none of these layouts (the message lists them).
    """
    from .sequences import is_sequence, read_sequence

    p = Path(path)
    if not p.is_dir():
        raise FileNotFoundError(f"{p}: no such folder")
    if is_7scenes(p):
        return SevenScenesSequence(p, **kwargs)
    if is_tum_rgbd(p):
        return TumRgbdSequence(p, **kwargs)
    if is_sequence(p) or (p / "intrinsics.json").is_file() and not (p / "depth").is_dir():
        return read_sequence(p, **kwargs)
    if (p / "depth").is_dir():
        return PlainFolderSequence(p, **kwargs)
    raise ValueError(f"{p}: not a recording folder: expected 7-Scenes frames (frame-XXXXXX.depth.png), a TUM RGB-D "
                     "folder (rgb.txt, depth.txt), a sequence folder (intrinsics.json, poses.txt) or rgb/ + depth/ "
                     "with intrinsics.json")
