"""Real recordings: TUM RGB-D folders as sequences of :class:`semmatch.io.Frame`.

A TUM RGB-D folder (https://cvg.cit.tum.de/data/datasets/rgbd-dataset/file_formats)::

    <folder>/rgb.txt            "timestamp filename" per line, '#' comments
    <folder>/depth.txt          the same for 16-bit depth PNGs (value / 5000 = metres)
    <folder>/groundtruth.txt    optional: "timestamp tx ty tz qx qy qz qw" (T_world_camera)
    <folder>/intrinsics.json    optional: our intrinsics file (wins over the defaults)

Colour and depth images are associated by timestamp as TUM's ``associate.py`` does (greedy,
closest pairs first, each image used once, ``|dt| <= max_difference``); ground-truth poses are
interpolated at the colour timestamps (linear translation, slerp rotation) when the frame lies
between two ground-truth samples at most ``max_gt_gap`` apart.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Iterator
from collections.abc import Sequence as _SequenceABC
from pathlib import Path

import numpy as np

from .fusion import check_depth_units
from .geometry import Intrinsics
from .io import (
    Frame,
    frame_index,
    listed_file,
    read_depth,
    read_intrinsics,
    read_label_image,
    read_rgb,
    read_tum,
)

__all__ = [
    "TUM_INTRINSICS",
    "TumRgbdSequence",
    "is_tum_rgbd",
    "read_tum_rgbd",
    "read_file_list",
    "associate",
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


def is_tum_rgbd(path: PathLike) -> bool:
    """True when ``path`` is a folder with ``rgb.txt`` and ``depth.txt``."""
    p = Path(path)
    return (p / "rgb.txt").is_file() and (p / "depth.txt").is_file()


def read_file_list(path: PathLike) -> tuple[np.ndarray, list[str]]:
    """Read a TUM list file (``timestamp filename ...``): timestamps (N,) and file names.

    Raises
    ------
    ValueError
        A line without two fields or with a timestamp that is not a number, or duplicate
        timestamps (the message gives the file and line).
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file")
    stamps, names = [], []
    for lineno, line in enumerate(path.read_text().splitlines(), 1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        parts = line.replace(",", " ").split()
        if len(parts) < 2:
            raise ValueError(f"{path}:{lineno}: expected 'timestamp filename', got {line!r}")
        try:
            t = float(parts[0])
        except ValueError:
            raise ValueError(f"{path}:{lineno}: timestamp {parts[0]!r} is not a number") from None
        stamps.append(t)
        names.append(parts[1])
    t = np.asarray(stamps, dtype=np.float64)
    if len(np.unique(t)) != len(t):
        raise ValueError(f"{path}: duplicate timestamps")
    return t, names


def associate(a: np.ndarray, b: np.ndarray, max_difference: float = 0.02) -> np.ndarray:
    """Match two timestamp lists as TUM's ``associate.py`` (closest pairs first, one-to-one).

    Returns
    -------
    ndarray of int, shape (M, 2)
        Index pairs ``(i, j)`` with ``|a[i] - b[j]| <= max_difference``, sorted by ``i``.
    """
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    if len(a) == 0 or len(b) == 0:
        return np.zeros((0, 2), dtype=np.int64)
    order = np.argsort(b)
    bs = b[order]
    # candidates: for every a, the b neighbours within the window
    lo = np.searchsorted(bs, a - max_difference, side="left")
    hi = np.searchsorted(bs, a + max_difference, side="right")
    ii = np.repeat(np.arange(len(a)), hi - lo)
    jj = np.concatenate([np.arange(s, e) for s, e in zip(lo, hi)]) if len(ii) else np.zeros(0, int)
    jj = jj.astype(np.int64)
    diff = np.abs(a[ii] - bs[jj])
    used_a = np.zeros(len(a), dtype=bool)
    used_b = np.zeros(len(b), dtype=bool)
    pairs = []
    for k in np.argsort(diff, kind="stable"):
        i, j = ii[k], jj[k]
        if not used_a[i] and not used_b[j]:
            used_a[i] = used_b[j] = True
            pairs.append((i, order[j]))
    out = np.asarray(sorted(pairs), dtype=np.int64).reshape(-1, 2)
    return out


def interpolate_poses(
    stamps: np.ndarray, gt_stamps: np.ndarray, gt_poses: np.ndarray, max_gap: float = 0.1
) -> np.ndarray:
    """Ground-truth poses at ``stamps`` (N,4,4); NaN where no ground truth brackets the time.

    Translation is interpolated linearly, rotation by slerp, between the two ground-truth samples
    around each time, when they are at most ``max_gap`` seconds apart (an exact hit always counts).
    """
    from scipy.spatial.transform import Rotation

    stamps = np.asarray(stamps, dtype=np.float64)
    out = np.full((len(stamps), 4, 4), np.nan)
    if len(gt_stamps) == 0:
        return out
    order = np.argsort(gt_stamps)
    ts, Ps = np.asarray(gt_stamps)[order], np.asarray(gt_poses)[order]
    j = np.searchsorted(ts, stamps, side="right")
    exact = (j > 0) & (ts[np.clip(j - 1, 0, len(ts) - 1)] == stamps)
    j0 = np.clip(j - 1, 0, len(ts) - 1)
    j1 = np.clip(j, 0, len(ts) - 1)
    inside = (j > 0) & (j < len(ts)) & (ts[j1] - ts[j0] <= max_gap)
    ok = inside | exact
    if not ok.any():
        return out
    idx = np.flatnonzero(ok)
    a, b = j0[idx], np.where(exact[idx], j0[idx], j1[idx])
    span = ts[b] - ts[a]
    w = np.where(span > 0, (stamps[idx] - ts[a]) / np.where(span > 0, span, 1), 0.0)
    ra = Rotation.from_matrix(Ps[a, :3, :3])
    rb = Rotation.from_matrix(Ps[b, :3, :3])
    delta = (ra.inv() * rb).as_rotvec()
    R = (ra * Rotation.from_rotvec(delta * w[:, None])).as_matrix()
    out[idx] = np.eye(4)
    out[idx, :3, :3] = R
    out[idx, :3, 3] = Ps[a, :3, 3] * (1 - w[:, None]) + Ps[b, :3, 3] * w[:, None]
    return out


def _span(t: np.ndarray) -> str:
    return f"{t.min():.3f}..{t.max():.3f}" if len(t) else "empty"


class TumRgbdSequence(_SequenceABC):
    """Lazy, random-access TUM RGB-D sequence: ``len(seq)``, ``seq[i] -> Frame``.

    Parameters
    ----------
    path : path
        The TUM folder.
    intrinsics : Intrinsics, optional
        Camera; default: ``<path>/intrinsics.json`` when present, else the published TUM
        calibration chosen from ``freiburg1/2/3`` in the folder name (``default`` otherwise).
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
        Check the median depth of every frame read (:func:`semmatch.fusion.check_depth_units`).

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
        both time ranges), too many unmatched frames, or a ground truth that covers no frame.
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
        pairs = associate(t_rgb, t_dep, max_difference)
        rgb_txt, dep_txt = self.path / "rgb.txt", self.path / "depth.txt"
        if len(pairs) == 0:
            raise ValueError(
                f"{rgb_txt} and {dep_txt}: no colour/depth pair within {max_difference} s "
                f"(colour times {_span(t_rgb)}, depth times {_span(t_dep)}); unmatched timestamps"
            )
        n_bad = len(t_rgb) - len(pairs)
        if n_bad:
            matched = np.zeros(len(t_rgb), dtype=bool)
            matched[pairs[:, 0]] = True
            first = ", ".join(f"{t:.6f}" for t in t_rgb[~matched][:3])
            msg = (
                f"{rgb_txt}: {n_bad} of {len(t_rgb)} colour frames have no depth image in {dep_txt} "
                f"within {max_difference} s (first: {first})"
            )
            if n_bad > max_unmatched * len(t_rgb):
                raise ValueError(msg + f"; more than {max_unmatched:.0%} unmatched timestamps")
            warnings.warn(msg + "; they are skipped", UserWarning, stacklevel=2)
        self.timestamps = t_rgb[pairs[:, 0]]
        self.depth_timestamps = t_dep[pairs[:, 1]]
        # entries stay inside the folder (no absolute paths, no '..'): semmatch.io.listed_file
        self._rgb = [listed_file(self.path, f_rgb[i], str(rgb_txt)) for i in pairs[:, 0]]
        self._depth = [listed_file(self.path, f_dep[j], str(dep_txt)) for j in pairs[:, 1]]
        self.intrinsics = intrinsics or self._default_intrinsics()
        self.labels_dir = Path(labels) if labels is not None else None
        self.check_units = check_units
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

    def _default_intrinsics(self) -> Intrinsics:
        if (self.path / "intrinsics.json").is_file():
            return read_intrinsics(self.path / "intrinsics.json")
        name = self.path.resolve().name.lower()
        for key, intr in TUM_INTRINSICS.items():
            if key in name:
                return intr
        return TUM_INTRINSICS["default"]

    def __len__(self) -> int:
        return len(self._rgb)

    @property
    def has_poses(self) -> bool:
        """True when every frame has a ground-truth pose."""
        return self.poses is not None and bool(np.isfinite(self.poses).all())

    def __getitem__(self, i):  # type: ignore[override]
        if isinstance(i, slice):
            return [self[j] for j in range(*i.indices(len(self)))]
        i = frame_index(i, len(self))
        rp, dp = self._rgb[i], self._depth[i]
        rgb = read_rgb(rp)  # 16-bit colour scaled, not wrapped to its low byte
        depth = read_depth(dp, self.intrinsics.depth_scale)
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
        return f"TumRgbdSequence({str(self.path)!r}, frames={len(self)})"


def read_tum_rgbd(path: PathLike, intrinsics: Intrinsics | None = None, **kwargs) -> TumRgbdSequence:
    """Open a TUM RGB-D folder as a sequence (see :class:`TumRgbdSequence`)."""
    return TumRgbdSequence(path, intrinsics, **kwargs)
