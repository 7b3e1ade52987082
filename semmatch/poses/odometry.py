"""Camera poses of recordings without them: RGB-D odometry.

Tracker (:func:`estimate_poses`): multi-scale frame-to-frame RGB-D odometry with the kernels of
``open3d.t.pipelines.odometry``, made repeatable run to run by :mod:`semmatch.poses.rgbd_odometry`
(the hybrid depth + intensity residual, with point-to-plane where it fails; docs/recordings.md
says how this was chosen on real and simulated frames), chained, then refined by a pose graph
(:func:`semmatch.poses.pose_graph.refine_pose_graph`). The first pose is ``init_pose`` (identity by
default; pass the known start pose, :func:`start_pose`, to build maps in the world frame).
Trajectory errors against ground truth are :mod:`semmatch.poses.trajectory_metrics`; how much drift
the pose graph removes is measured in docs/protocol.md ("Odometry").
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import replace

import numpy as np

from ..io import Frame, check_depth_units, depth_to_uint16
from ..io.geometry import check_pose
from ..runtime.engine import default_device
from .pose_graph import CompressedDepths, refine_pose_graph
from .trajectory_metrics import rotation_deg

__all__ = ["estimate_poses", "shrink_frame", "ground_truth_poses", "start_pose", "anchor_to_ground_truth"]

#: a frame with fewer valid depth pixels than this share is a sensor dropout (as in fusion)
MIN_VALID_DEPTH = 0.001

#: how :func:`estimate_poses` picks among its residuals' estimates of one frame pair
SELECTIONS = ("first", "misfit")


def _depth_mm(depth: np.ndarray, where: str) -> np.ndarray:
    check_depth_units(depth, where=where)
    return depth_to_uint16(depth)


def estimate_poses(
    seq: Iterable[Frame],
    *,
    residual: str = "hybrid",
    robust: bool = True,
    select: str = "first",
    max_step: float = 0.5,
    prior: np.ndarray | None = None,
    prior_tolerance: tuple[float, float] | None = (0.1, 10.0),
    init_pose: np.ndarray | None = None,
    depth_max: float = 5.0,
    pose_graph: bool = True,
    downsample: int = 1,
    device: str | None = None,
    progress: bool = False,
) -> np.ndarray:
    """Estimate ``T_world_camera`` of every frame by RGB-D tracking (recorded poses are ignored).

    Parameters
    ----------
    seq : sequence or iterable of Frame
        Frames with metric depth and RGB (e.g. :func:`semmatch.io.read_sequence`,
        :func:`semmatch.io.recordings.read_tum_rgbd`).
    residual : {"hybrid", "point-to-plane", "intensity"}
        Residual of the frame-to-frame odometry (Open3D ``Method``): geometric + photometric,
        geometric, or photometric. Hybrid is the default: on real Kinect frames (7-Scenes red
        kitchen, frames 0-499) point-to-plane drifts (docs/recordings.md).
    robust : bool
        Frame-to-frame: also run the point-to-plane/hybrid alternative (point-to-plane alone
        slides along planar views; hybrid alone fails where the image has no texture), each
        started from the previous motion (constant velocity); from rest only when nothing
        converged.
    select : {"first", "misfit"}
        With ``robust``: "first" keeps ``residual``'s estimate whenever it is plausible and
        uses the alternative only when it is not (diverged, no correspondences, rejected by the
        prior); "misfit" keeps the estimate whose warped intensities and depths fit the previous
        frame best (the earlier rule: on real frames it picks point-to-plane's smoother but
        drifting estimates).
    max_step : float
        Largest plausible motion between consecutive frames (metres; rotations up to 90
        degrees); larger estimates are rejected as divergence.
    prior : (N, 4, 4), optional
        Rough poses from another sensor (wheel odometry, IMU, a simulated noisy estimate): their
        frame-to-frame motions seed the tracker, which then refines them with RGB-D data. Needed
        when the camera turns faster than RGB-D odometry converges (tens of degrees per frame).
    prior_tolerance : (metres, degrees) or None
        With a prior: a frame-to-frame motion that differs from the prior's by more than this
        translation or rotation is rejected as a false convergence (a repetitive or planar
        view can pull the tracker half a metre off); when every candidate is rejected the
        prior's motion is used. None: the prior only seeds the tracker.
    init_pose : (4, 4), optional
        Pose of the first frame (default identity).
    depth_max : float
        Ignore depth beyond this (metres).
    pose_graph : bool
        Refine the chained poses with :func:`refine_pose_graph` (neighbour and loop-closure
        edges).
    downsample : int
        Track on frames shrunk by this factor (RGB area-averaged, depth by nearest pixel so
        that no depth is invented at edges; intrinsics scaled to match).
    device : str, optional
        Open3D device (default :func:`semmatch.runtime.engine.default_device`).
    progress : bool
        Show a tqdm bar.

    Returns
    -------
    ndarray (N, 4, 4) float64

    Raises
    ------
    ValueError
        Unknown residual or selection, empty sequence, depth in the wrong unit, a prior of
        the wrong shape, frames of different sizes.

    Warns
    -----
    UserWarning
        Frames for which no residual converged to a plausible motion (their motion is the
        prior's, or extrapolated without a prior); the message lists them.
    """
    from ..runtime.progress import tqdm

    n = len(seq) if hasattr(seq, "__len__") else None
    if prior is not None:
        prior = np.asarray(prior, dtype=np.float64)
        if prior.ndim != 3 or prior.shape[1:] != (4, 4) or (n is not None and len(prior) != n):
            raise ValueError(f"prior must have shape (N,4,4) for the {n} frames, got {prior.shape}")
    if int(downsample) < 1:
        raise ValueError(f"downsample must be an integer >= 1, got {downsample}")
    name = str(getattr(seq, "path", "sequence"))
    if select not in SELECTIONS:
        raise ValueError(f"select must be one of {SELECTIONS}, got {select!r}")
    tracker = _Tracker(residual=residual, robust=robust, select=select, max_step=max_step, prior=prior,
                       prior_tolerance=prior_tolerance, depth_max=depth_max, device=device,
                       T=np.eye(4) if init_pose is None else check_pose(init_pose, what="init_pose").copy())
    poses: list[np.ndarray] = []
    depths_mm = CompressedDepths()  # kept for the pose graph (depth only, losslessly compressed)
    intrinsics = None
    frames = seq if int(downsample) == 1 else (shrink_frame(f, int(downsample)) for f in seq)
    for i, f in enumerate(tqdm(frames, total=n, desc="odometry", disable=not progress, leave=False)):
        where = f"{name} frame {getattr(f, 'index', i)}"
        d_mm = _depth_mm(f.depth, where)
        if intrinsics is None:
            intrinsics = f.intrinsics
        elif f.intrinsics != intrinsics or d_mm.shape != tuple(intrinsics.shape):
            raise ValueError(f"{where}: frame size/intrinsics differ from the first frame's")
        if pose_graph:
            depths_mm.append(d_mm)
        poses.append(tracker.step(i, f, d_mm))
    if not poses:
        raise ValueError(f"{name}: the sequence has no frames")
    if tracker.T_prev is None:
        raise ValueError(f"{name}: none of its {len(poses)} frame(s) has usable depth (all empty or out of range)")
    tracker.warn(name, len(poses))
    out = np.stack(poses)
    if pose_graph and len(out) > 2:
        out = refine_pose_graph(depths_mm, intrinsics, out, depth_max=depth_max, device=device,
                                progress=progress, name=name)
    return out


class _Tracker:
    """Frame-to-frame RGB-D tracking (the steps of :func:`estimate_poses`).

    It keeps the last tracked frame (the reference of the next one), its pose and index, and the
    per-frame motion used for constant-velocity guesses; frames without usable depth
    (dropouts) and frames where nothing converged (lost) are collected for one warning each.
    """

    def __init__(self, *, residual: str, robust: bool, select: str, max_step: float, prior: np.ndarray | None,
                 prior_tolerance: tuple[float, float] | None, depth_max: float, device: str | None,
                 T: np.ndarray) -> None:
        from .rgbd_odometry import METHODS

        if residual not in METHODS:
            raise ValueError(f"residual must be one of {METHODS}, got {residual!r}")
        # the chosen residual and, for robustness in geometrically degenerate views (a wall and
        # the floor), the other geometric/photometric one; the smaller photometric + depth misfit wins
        extra = ["point-to-plane", "hybrid"] if robust else []
        self.methods = [residual] + [m for m in extra if m != residual]
        self.iterations = (30, 15, 8)  # per pyramid level, coarsest first
        self.robust, self.select, self.max_step, self.depth_max = robust, select, max_step, depth_max
        self.prior, self.prior_tolerance = prior, prior_tolerance
        self.device = device or default_device()
        self.T = T
        self.T_prev: np.ndarray | None = None  # pose of the last tracked frame
        self.i_prev = -1  # its index
        self.prev = None  # its image pyramid (semmatch.poses.rgbd_odometry.rgbd_pyramid)
        self.prev_frame: Frame | None = None
        self.motion = np.eye(4)  # per-frame motion (constant-velocity guesses)
        self.lost: list[int] = []
        self.dropped: list[int] = []

    def step(self, i: int, f: Frame, d_mm: np.ndarray) -> np.ndarray:
        """The pose of frame ``i`` (depth ``d_mm`` in millimetres): tracked, or bridged over a dropout."""
        if np.count_nonzero((d_mm > 0) & (d_mm <= self.depth_max * 1000.0)) < MIN_VALID_DEPTH * d_mm.size:
            self.dropped.append(getattr(f, "index", i))
            return self._bridge(i)
        from .rgbd_odometry import rgbd_pyramid

        rgbd = rgbd_pyramid(d_mm, f.rgb, f.intrinsics.K, levels=len(self.iterations), depth_max=self.depth_max,
                            device=self.device)
        if self.prev is not None:
            gap = i - self.i_prev  # > 1 after dropouts: the motion since the last tracked frame
            best = self._relative_motion(i, f, rgbd, gap)
            self.T = self.T_prev @ best  # best = T_prev_cur
            # per-frame motion for the constant-velocity guesses (the step's rotation and
            # translation spread over the frames of a gap)
            self.motion = best if gap == 1 else _fractional_motion(best, gap)
        self.prev, self.prev_frame = rgbd, f
        self.T_prev, self.i_prev = self.T.copy(), i
        return self.T.copy()

    def _bridge(self, i: int) -> np.ndarray:
        """Pose of an untracked frame: the prior's motion (else constant velocity) from the last
        tracked frame, which stays the reference of the next one."""
        if self.T_prev is None:
            return self.T.copy()
        if self.prior is not None:
            return self.T_prev @ np.linalg.inv(self.prior[self.i_prev]) @ self.prior[i]
        return self.T_prev @ np.linalg.matrix_power(self.motion, i - self.i_prev)

    def _relative_motion(self, i: int, f: Frame, rgbd, gap: int) -> np.ndarray:
        """``T_prev_cur``: the best plausible odometry result over the initial guesses and residuals."""
        inits = [self.motion if gap == 1 else np.linalg.matrix_power(self.motion, gap)]
        prior_motion = None
        if self.prior is not None:
            prior_motion = np.linalg.inv(self.prior[self.i_prev]) @ self.prior[i]
            inits = [prior_motion] + inits
        best = None
        for init in inits + [np.eye(4)]:  # rest only when nothing else converged
            best = self._best_candidate(f, rgbd, init, prior_motion)
            if best is not None:
                return best
        # tracking lost: the prior's motion, else constant velocity
        self.lost.append(getattr(f, "index", i))
        return inits[-1] if prior_motion is None else prior_motion

    def _best_candidate(self, f: Frame, rgbd, init: np.ndarray,
                        prior_motion: np.ndarray | None) -> np.ndarray | None:
        """The residual whose plausible result (started at ``init``) fits the previous frame best, or None."""
        from .rgbd_odometry import multi_scale_odometry

        best, best_cost = None, np.inf
        for m in self.methods:
            try:
                Tm = multi_scale_odometry(rgbd, self.prev, init, method=m, iterations=self.iterations)[0]
            except RuntimeError:  # no correspondences (singular system)
                continue
            if not _plausible(Tm, self.max_step):
                continue
            if (prior_motion is not None and self.prior_tolerance is not None
                    and not _agrees(Tm, prior_motion, *self.prior_tolerance)):
                continue
            if self.select == "first":
                return Tm  # the first plausible estimate, in the order of self.methods
            cost = _misfit(f, self.prev_frame, Tm, self.depth_max) if self.robust else 0.0
            if cost < best_cost:
                best, best_cost = Tm, cost
        return best

    def warn(self, name: str, n_frames: int) -> None:
        """One warning for the dropouts and one for the frames where tracking was lost."""
        import warnings

        if self.dropped:
            warnings.warn(f"{name}: {len(self.dropped)} of {n_frames} frame(s) had (almost) no valid depth and were "
                          f"not tracked (sensor dropouts; first: {self.dropped[:5]}); their poses follow the "
                          + ("prior" if self.prior is not None else "motion of the frames before"),
                          UserWarning, stacklevel=3)
        if self.lost:
            warnings.warn(
                f"{name}: RGB-D odometry found no solution for {len(self.lost)} frame(s) (first: {self.lost[:5]}); "
                + ("their motion was taken from the prior" if self.prior is not None
                   else "their motion was extrapolated from the previous frame"),
                UserWarning,
                stacklevel=3,
            )


def _fractional_motion(motion: np.ndarray, steps: int) -> np.ndarray:
    """The rigid motion that, applied ``steps`` times, gives ``motion`` (rotation by the same axis
    at 1/steps of the angle, translation along the same screw approximated linearly)."""
    from scipy.spatial.transform import Rotation

    out = np.eye(4)
    out[:3, :3] = Rotation.from_rotvec(Rotation.from_matrix(motion[:3, :3]).as_rotvec() / steps).as_matrix()
    out[:3, 3] = motion[:3, 3] / steps
    return out


def shrink_frame(frame: Frame, factor: int) -> Frame:
    """A frame shrunk by an integer ``factor``: RGB area-averaged, depth (and labels) by nearest pixel.

    Parameters
    ----------
    frame : Frame
    factor : int
        >= 1; the new size is ``(W // factor, H // factor)``.

    Returns
    -------
    Frame
        Same pose and index; intrinsics scaled to the new size.
    """
    import cv2

    if factor == 1:
        return frame
    H, W = frame.depth.shape
    w, h = W // factor, H // factor
    if w < 8 or h < 8:
        raise ValueError(f"frame {frame.index}: {W}x{H} shrunk by {factor} is too small")
    rgb = cv2.resize(np.ascontiguousarray(frame.rgb), (w, h), interpolation=cv2.INTER_AREA)
    depth = cv2.resize(np.ascontiguousarray(frame.depth), (w, h), interpolation=cv2.INTER_NEAREST)
    labels = None if frame.labels is None else cv2.resize(frame.labels, (w, h), interpolation=cv2.INTER_NEAREST)
    return replace(frame, rgb=rgb, depth=depth, labels=labels, intrinsics=frame.intrinsics.scaled(w, h))


def _plausible(T: np.ndarray, max_step: float) -> bool:
    if not np.isfinite(T).all():
        return False
    angle = np.arccos(np.clip((np.trace(T[:3, :3]) - 1) / 2, -1.0, 1.0))
    return bool(np.linalg.norm(T[:3, 3]) <= max_step and angle <= np.radians(90.0))


def _agrees(T: np.ndarray, ref: np.ndarray, max_t: float, max_deg: float) -> bool:
    """True when motions ``T`` and ``ref`` (4,4) differ by at most ``max_t`` m and ``max_deg`` degrees."""
    D = np.linalg.inv(ref) @ T
    return bool(np.linalg.norm(D[:3, 3]) <= max_t and rotation_deg(D[:3, :3]) <= max_deg)


def _misfit(cur: Frame, prev: Frame, T_prev_cur: np.ndarray, depth_max: float, stride: int = 4) -> float:
    """Photometric + depth misfit of ``T_prev_cur``: previous pixels warped into the current frame.

    Mean absolute grey difference (0..1) over pixels whose depths agree within 5 cm, plus the
    share of previous pixels that land outside the current frame or disagree in depth.
    """
    from ..io.geometry import backproject, project

    intr = prev.intrinsics
    d = np.where(prev.depth <= depth_max, prev.depth, 0)
    pts, idx = backproject(d, intr, stride=stride)
    if len(pts) == 0:
        return np.inf
    inv = np.linalg.inv(T_prev_cur)
    uv, z = project(pts @ inv[:3, :3].T + inv[:3, 3], intr)
    u = np.rint(uv[:, 0]).astype(np.int64)
    v = np.rint(uv[:, 1]).astype(np.int64)
    H, W = intr.shape
    inside = (z > 0) & (u >= 0) & (u < W) & (v >= 0) & (v < H)
    u, v, z, idx = u[inside], v[inside], z[inside], idx[inside]
    dz = cur.depth[v, u]
    ok = (dz > 0) & (np.abs(dz - z) < 0.05)
    if ok.sum() < 10:
        return np.inf
    grey_c = cur.rgb.astype(np.float32).mean(axis=2) / 255.0
    grey_p = prev.rgb.astype(np.float32).mean(axis=2).reshape(-1) / 255.0
    photo = float(np.abs(grey_c[v[ok], u[ok]] - grey_p[idx[ok]]).mean())
    return photo + (1.0 - ok.sum() / len(pts))


def ground_truth_poses(seq) -> np.ndarray | None:
    """The true poses of a recording, where it has them (for reports and a known start, never for estimates).

    A simulated real-like sequence folder keeps them in ``poses_gt.txt`` (its ``poses.txt``
    holds a drifting estimate); any other sequence folder in ``poses.txt`` (the data contract);
    a TUM RGB-D folder in ``groundtruth.txt`` (its ``poses``). Anything else has none.

    Parameters
    ----------
    seq : sequence of Frame
        A :class:`~semmatch.io.SequenceReader` (or its in-memory copy) or a TUM RGB-D sequence.

    Returns
    -------
    ndarray (N, 4, 4) or None
    """
    from pathlib import Path

    from ..io import read_tum

    path = getattr(seq, "path", None)
    if path is not None and (Path(path) / "poses_gt.txt").is_file():
        return read_tum(Path(path) / "poses_gt.txt")[1]
    if getattr(seq, "poses", None) is not None:
        return np.asarray(seq.poses, dtype=np.float64)
    return None


def start_pose(true_poses: np.ndarray | None) -> np.ndarray | None:
    """The known first pose of a recording: its first true pose where that is finite, else None.

    Parameters
    ----------
    true_poses : ndarray (N, 4, 4) or None
        E.g. :func:`ground_truth_poses`.

    Returns
    -------
    ndarray (4, 4) or None
        None: the start is unknown (:func:`estimate_poses` then starts at the identity).
    """
    if true_poses is None or len(true_poses) == 0 or not np.isfinite(true_poses[0]).all():
        return None
    return np.asarray(true_poses[0], dtype=np.float64).copy()


def anchor_to_ground_truth(poses: np.ndarray, true_poses: np.ndarray | None,
                           *, name: str = "sequence") -> tuple[np.ndarray, int | None]:
    """Move an estimated trajectory so that it starts where the ground truth starts.

    When the ground truth's first frame has a pose, :func:`estimate_poses` already started there
    (``init_pose=start_pose(...)``) and nothing changes. When the ground truth starts later
    (a recording whose motion capture begins after the camera), the whole chain is moved
    rigidly so that the first frame with ground truth sits at its true pose, and a warning says
    so (otherwise the chain would start at the identity, far from the ground truth's frame).

    Parameters
    ----------
    poses : ndarray (N, 4, 4)
        Estimated ``T_world_camera``.
    true_poses : ndarray (N, 4, 4) or None
        Ground truth with NaN rows where unknown.
    name : str
        What the recording is, for the warning.

    Returns
    -------
    (poses, first)
        The anchored poses and the index of the first frame with ground truth (None: none has).
    """
    import warnings

    if true_poses is None:
        return poses, None
    ok = np.flatnonzero(np.isfinite(np.asarray(true_poses)).all(axis=(1, 2)))
    if len(ok) == 0:
        return poses, None
    k = int(ok[0])
    if k == 0:
        return poses, 0
    warnings.warn(f"{name}: the ground truth starts at frame {k}, not 0; the estimated trajectory is anchored "
                  f"at frame {k}'s true pose (frames 0-{k - 1} are placed by odometry alone, and ATE/RPE use only "
                  "frames with ground truth)", UserWarning, stacklevel=2)
    return np.asarray(true_poses[k]) @ np.linalg.inv(poses[k]) @ poses, k
