"""Poses for a recording that has none: RGB-D odometry (:func:`~semmatch.poses.odometry.estimate_poses`), cached.

``--estimate-poses`` of every verb that takes a sequence comes here. The trajectory is anchored
at the ground truth where the recording has one (:func:`~semmatch.poses.odometry.anchor_to_ground_truth`)
and cached as a TUM file in the user cache folder (``$SEMMATCH_CACHE_DIR/poses`` when that is
set, else ``platformdirs.user_cache_dir("semmatch")/poses``; the map index cache's folder's
sibling), keyed by a digest of the frames used (each frame file's path, size and modification
time; the decoded frames for a reader that names no files) and the odometry settings. The cache
file is written atomically; the next call with the same frames and settings reads it instead of
running the odometry again.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import numpy as np

__all__ = ["POSES_CACHE_VERSION", "poses_cache_dir", "poses_cache_key", "estimate_recording_poses"]

#: version of the cached trajectories (bump when the odometry's results change)
POSES_CACHE_VERSION = 1


def poses_cache_dir(where: str | os.PathLike | None = "user") -> Path:
    """The folder of cached trajectories.

    Parameters
    ----------
    where : "user", path or None
        ``"user"`` or None: ``$SEMMATCH_CACHE_DIR/poses`` when set, else the user cache folder's
        ``poses``; anything else: that folder.

    Returns
    -------
    Path
        The folder (not created here).
    """
    if where is None or (isinstance(where, str) and where == "user"):
        env = os.environ.get("SEMMATCH_CACHE_DIR")  # the variable the map index cache follows too
        if env:
            return Path(env).expanduser() / "poses"
        import platformdirs

        return Path(platformdirs.user_cache_dir("semmatch")) / "poses"
    return Path(where).expanduser()


def poses_cache_key(seq, settings: dict) -> str:
    """A digest of the frames of ``seq`` and the odometry ``settings`` (24 hex digits).

    Each frame contributes its files' resolved paths, sizes and modification times
    (:func:`semmatch.io.readers.frame_files`), or, for a reader that names no files, its
    decoded colour and depth; the camera, the number of frames and their timestamps always
    count (a reader whose frames share one file, a bag, still keys each range apart), and a
    bag's topics (``seq.topics``) too.

    Parameters
    ----------
    seq : sequence of Frame
    settings : dict
        JSON-able odometry settings (residual, pose graph, start pose, prior ...).

    Returns
    -------
    str
    """
    from ..io.readers import frame_files

    h = hashlib.sha256()
    head = {"version": POSES_CACHE_VERSION, "n": len(seq), "settings": settings, "intrinsics": seq.intrinsics.to_dict()}
    if getattr(seq, "topics", None):  # a bag: which of its topics the frames are read from
        head["topics"] = dict(seq.topics)
    h.update(json.dumps(head, sort_keys=True, default=str).encode())
    h.update(np.ascontiguousarray(getattr(seq, "timestamps", np.arange(len(seq))), dtype=np.float64).tobytes())
    for i in range(len(seq)):
        files = frame_files(seq, i)
        if files:
            for f in files:
                st = Path(f).stat()
                h.update(f"{Path(f).resolve()}|{st.st_size}|{st.st_mtime_ns}\n".encode())
        else:
            f = seq[i]
            h.update(np.ascontiguousarray(f.rgb).tobytes())
            h.update(np.ascontiguousarray(f.depth).tobytes())
    return h.hexdigest()[:24]


def _digest(a: np.ndarray | None) -> str | None:
    return None if a is None else hashlib.sha256(np.ascontiguousarray(a, dtype=np.float64).tobytes()).hexdigest()[:16]


def estimate_recording_poses(seq, *, name: str = "recording", residual: str = "hybrid", pose_graph: bool = True,
                             prior: bool = False, device: str | None = None, progress: bool = False,
                             cache: str | os.PathLike | None = "user") -> tuple[np.ndarray, dict]:
    """Estimate the poses of every frame of a recording by RGB-D odometry, or read them from the cache.

    The odometry starts at the ground truth's first pose where the recording has one
    (:func:`~semmatch.poses.odometry.start_pose`), else at the identity, and the trajectory is
    anchored at the first frame with ground truth.

    Parameters
    ----------
    seq : sequence of Frame
        Any reader (:func:`semmatch.io.readers.open_recording`).
    name : str
        The recording, for messages.
    residual, pose_graph, device, progress
        As :func:`~semmatch.poses.odometry.estimate_poses`.
    prior : bool
        Seed the odometry with the recording's own (rough) poses.
    cache : "user", path or False/None
        Where trajectories are cached (:func:`poses_cache_dir`); False: neither read nor written.

    Returns
    -------
    poses : ndarray (N, 4, 4)
        ``T_world_camera``.
    info : dict
        ``cached`` (read from the cache), ``cache_file`` (or None), ``ground_truth`` ((N,4,4) or
        None: :func:`~semmatch.poses.odometry.ground_truth_poses`), ``gt_first_frame``.
    """
    from ..io import read_tum, write_tum
    from .odometry import anchor_to_ground_truth, estimate_poses, ground_truth_poses, start_pose

    gt = ground_truth_poses(seq)
    if gt is not None and len(gt) != len(seq):  # a frame range of a recording whose true poses lie beside it
        keep, base = getattr(seq, "indices", None), getattr(seq, "base", None)
        gt = gt[list(keep)] if keep is not None and base is not None and len(gt) == len(base) else None
    prior_poses = np.asarray(seq.poses, dtype=np.float64) if prior and getattr(seq, "poses", None) is not None else None
    init = start_pose(gt)
    settings = {"residual": residual, "pose_graph": bool(pose_graph), "prior": _digest(prior_poses),
                "init": _digest(init), "gt": _digest(gt)}
    file = None
    if cache is not False and cache is not None:
        file = poses_cache_dir(cache) / f"{poses_cache_key(seq, settings)}.txt"
        if file.is_file():
            _, poses = read_tum(file)
            if len(poses) == len(seq):
                first = anchor_to_ground_truth(poses, gt, name=name)[1] if gt is not None else None
                return poses, {"cached": True, "cache_file": str(file), "ground_truth": gt, "gt_first_frame": first}
    poses = estimate_poses(seq, init_pose=init, prior=prior_poses, residual=residual, pose_graph=pose_graph,
                           device=device, progress=progress)
    poses, first = anchor_to_ground_truth(poses, gt, name=name)
    if file is not None:
        file.parent.mkdir(parents=True, exist_ok=True)
        write_tum(file, np.arange(len(poses), dtype=np.float64), poses)
    return poses, {"cached": False, "cache_file": None if file is None else str(file), "ground_truth": gt,
                   "gt_first_frame": first}
