"""The reading checks every recording reader and the sequence folder share (no silent wrong reading).

* :func:`check_poses`: camera positions finite and within :data:`MAX_POSITION` of the origin,
  rotation blocks orthonormal with determinant +1 (within :data:`ROTATION_TOLERANCE`);
* :func:`check_depth_scale`: a depth scale that contradicts the depth statistics (millimetre PNGs
  read at TUM's 1/5000 m, which shrinks the room five times) is refused;
* :func:`check_label_ids`: label images hold ids of the category table (:mod:`semmatch.io.labels`).

Each raises a ``ValueError`` naming the file or frame and what is wrong.
"""

from __future__ import annotations

import os
from collections.abc import Sequence

import numpy as np

from .images import read_image

__all__ = ["MAX_POSITION", "ROTATION_TOLERANCE", "NEAREST_MEDIAN_DEPTH", "DEPTH_HOLE", "check_poses",
           "check_depth_scale", "check_label_ids", "read_raw_depth"]

PathLike = str | os.PathLike

#: largest camera coordinate a trajectory may hold (metres): no recorded scene spans 10 km
MAX_POSITION = 1e4

#: largest deviation of ``R.T @ R`` from the identity (per entry) a pose's rotation block may have
ROTATION_TOLERANCE = 1e-3

#: depth scale check (:func:`check_depth_scale`): no RGB-D camera of these recordings measures a
#: scene whose median depth is nearer than this (metres); Kinect v1's range starts at 0.4-0.5 m
NEAREST_MEDIAN_DEPTH = 0.5

#: 16-bit depth values that mean "no measurement" (0, and 65535 as 7-Scenes writes its holes)
DEPTH_HOLE = 65535


def check_poses(poses: np.ndarray | None, *, where: str, names: Sequence[str] | None = None) -> None:
    """Refuse camera poses that are not rigid or lie beyond :data:`MAX_POSITION` (frames without a pose pass).

    A frame whose pose holds NaN or inf is "unknown" (readers mark frames without ground truth so)
    and is skipped; every other pose must have a finite position within :data:`MAX_POSITION`
    metres of the origin, a last row ``0 0 0 1`` and an orthonormal rotation block with
    determinant +1 (within :data:`ROTATION_TOLERANCE`).

    Parameters
    ----------
    poses : ndarray (N, 4, 4) or None
        ``T_world_camera`` per frame; None: nothing to check.
    where : str
        The recording, for the message.
    names : sequence of str, optional
        What each pose was read from (e.g. its ``frame-000012.pose.txt``), named instead of the frame.

    Raises
    ------
    ValueError
        The first bad pose: the message names the frame (or its file) and what is wrong.
    """
    if poses is None:
        return
    P = np.asarray(poses, dtype=np.float64).reshape(-1, 4, 4)
    known = np.flatnonzero(np.isfinite(P).all(axis=(1, 2)))
    if not len(known):
        return
    K = P[known]
    far = np.abs(K[:, :3, 3]).max(axis=1) > MAX_POSITION
    R = K[:, :3, :3]
    err = np.abs(np.einsum("nji,njk->nik", R, R) - np.eye(3)).max(axis=(1, 2))
    bad_rot = (err > ROTATION_TOLERANCE) | (np.linalg.det(R) < 0)
    bad_row = np.abs(K[:, 3] - [0, 0, 0, 1]).max(axis=1) > 1e-4
    bad = np.flatnonzero(far | bad_rot | bad_row)
    if not len(bad):
        return
    k, i = int(bad[0]), int(known[bad[0]])
    what = names[i] if names is not None else f"{where}: frame {i}"
    n = f" ({len(bad)} of {len(P)} poses are bad)" if len(bad) > 1 else ""
    if far[k]:
        raise ValueError(f"{what}: camera position {K[k, :3, 3].tolist()} lies beyond {MAX_POSITION:g} m of the "
                         f"origin: a corrupt pose, or a trajectory in other units{n}")
    if bad_row[k]:
        raise ValueError(f"{what}: the pose's last row must be [0 0 0 1], got {K[k, 3].tolist()}{n}")
    raise ValueError(f"{what}: the pose's 3x3 block is not a rotation (|R^T R - I| up to {err[k]:.2g}, det "
                     f"{np.linalg.det(R[k]):.3g}; allowed {ROTATION_TOLERANCE:g} and +1){n}")


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


def check_depth_scale(depth_paths: Sequence[PathLike], depth_scale: float, *, where: str,
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


def check_label_ids(labels: np.ndarray, *, where: PathLike) -> np.ndarray:
    """Refuse a label image with ids outside the category table (:data:`semmatch.io.labels.NUM_CLASSES`).

    Parameters
    ----------
    labels : uint8 (H, W)
        Category ids as read (:func:`semmatch.io.read_label_image`).
    where : path
        The image, for the message.

    Returns
    -------
    ndarray
        ``labels`` itself.

    Raises
    ------
    ValueError
        An id outside ``0 .. NUM_CLASSES - 1`` (labels of another label table).
    """
    from .labels import NUM_CLASSES

    top = int(labels.max(initial=0))
    if top >= NUM_CLASSES:
        raise ValueError(f"{where}: label id {top} outside 0..{NUM_CLASSES - 1} (the category table of "
                         "semmatch.io.labels); labels of another label table?")
    return labels
