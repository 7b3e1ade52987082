"""Timestamped recordings: TUM's list files, matching two timestamp lists, poses at timestamps.

The time side of :mod:`semmatch.io.recordings` (which exports these names too):
:func:`read_file_list` reads a TUM list (``timestamp filename``), :func:`associate` pairs two
timestamp lists as TUM's ``associate.py`` does (closest pairs first, one-to-one),
:func:`associate_frames` pairs a recording's colour and depth frames with it (refusing a recording
that barely pairs), and :func:`interpolate_poses` gives ground-truth poses at other timestamps (linear translation,
slerp rotation; NaN where no sample brackets the time closely enough).
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path

import numpy as np

__all__ = ["read_file_list", "associate", "associate_frames", "interpolate_poses"]

PathLike = str | os.PathLike


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


def _span(t: np.ndarray) -> str:
    return f"{t.min():.3f}..{t.max():.3f}" if len(t) else "empty"


def associate_frames(t_rgb: np.ndarray, t_depth: np.ndarray, max_difference: float, max_unmatched: float, *,
                     rgb_where: str, depth_where: str) -> np.ndarray:
    """Pair a recording's colour and depth frames by timestamp (:func:`associate`); few may stay unmatched.

    Parameters
    ----------
    t_rgb, t_depth : ndarray (N,), (M,)
        Colour and depth timestamps (seconds).
    max_difference : float
        Association window (seconds).
    max_unmatched : float
        Fraction of colour frames allowed to have no depth partner (they are skipped with a warning).
    rgb_where, depth_where : str
        Where the colour and depth timestamps come from (list files, bag topics), for the messages.

    Returns
    -------
    ndarray of int, shape (K, 2)
        Index pairs ``(colour, depth)`` sorted by colour index.

    Raises
    ------
    ValueError
        No pair within ``max_difference`` (the message gives both time ranges), or more than
        ``max_unmatched`` of the colour frames unmatched.

    Warns
    -----
    UserWarning
        Some colour frames have no depth partner (the first three times are named).
    """
    pairs = associate(t_rgb, t_depth, max_difference)
    if len(pairs) == 0:
        raise ValueError(
            f"{rgb_where} and {depth_where}: no colour/depth pair within {max_difference} s "
            f"(colour times {_span(t_rgb)}, depth times {_span(t_depth)}); unmatched timestamps"
        )
    n_bad = len(t_rgb) - len(pairs)
    if n_bad:
        matched = np.zeros(len(t_rgb), dtype=bool)
        matched[pairs[:, 0]] = True
        first = ", ".join(f"{t:.6f}" for t in t_rgb[~matched][:3])
        msg = (
            f"{rgb_where}: {n_bad} of {len(t_rgb)} colour frames have no depth image in {depth_where} "
            f"within {max_difference} s (first: {first})"
        )
        if n_bad > max_unmatched * len(t_rgb):
            raise ValueError(msg + f"; more than {max_unmatched:.0%} unmatched timestamps")
        warnings.warn(msg + "; they are skipped", UserWarning, stacklevel=3)
    return pairs


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
