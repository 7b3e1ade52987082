"""The robot online: one RGB-D frame at a time to a pose, labels and a growing semantic map.

:class:`RobotSession` is the streaming form of the offline chain (poses, ``transfer_sequence``,
``reconstruct``). For each frame it

1. finds the pose: given (true or external poses), or tracked frame to model
   (:class:`~semmatch.online.tracking.ModelTracker`: the person's map rendered from the predicted
   pose, the robot's own TSDF where the person's map has no surface, or the robot's TSDF alone
   without a person's map, KinectFusion style); the first pose comes from an initialiser
   (:mod:`semmatch.online.initialisation`; a given pose, or global registration onto the person's
   map), and while tracking is lost the session tries to relocalise;
2. transfers the person's labels into the frame with any registered method
   (:func:`semmatch.transfer.sequence.transfer_posed_frame`, the per-frame step of
   ``transfer_sequence``; ``fused`` with the frame's class probabilities);
3. integrates the frame and its labels into the robot's :class:`~semmatch.fusion.tsdf.SemanticTSDF`
   (:func:`semmatch.fusion.reconstruction.fuse_frame`, the per-frame step of ``fuse_sequence``).

A frame whose pose is unknown (lost, or not yet initialised) gets void labels (all 0) and is not
fused: nothing is guessed. The session and the batch verbs (``semmatch transfer``,
``semmatch reconstruct``) share their per-frame steps, so with the same poses the session's labels
and map are the batch verbs' byte for byte (tests/test_online.py checks both, API and verbs).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..io import Frame, SemanticMap
from ..io.geometry import check_pose
from .initialisation import Initialisation, Initialiser, given_pose, register_frame
from .tracking import LOST, TRACKED, ModelTracker, TrackingResult

__all__ = ["RobotSession", "FrameResult", "STATUSES"]

#: per-frame statuses: pose given by the caller; first pose found; tracked against the model;
#: relocalised after a loss; lost (labels void, not fused); waiting for a first pose (labels void)
STATUSES = ("given", "initialised", TRACKED, "relocalised", LOST, "initialising")


@dataclass
class FrameResult:
    """What :meth:`RobotSession.step` returns for one frame.

    Attributes
    ----------
    index : int
        The frame's index in its recording.
    status : str
        One of :data:`STATUSES`.
    pose : (4, 4) float64 or None
        ``T_world_camera`` in the person's map frame (None when lost or not initialised).
    labels : uint8 (H, W) or None
        Transferred labels (all 0 when the pose is unknown); None without a person's map.
    tracking : TrackingResult or None
        The tracker's fit (fitness, residual, model view) when the frame was tracked or lost.
    fused : bool
        Whether the frame was integrated into the robot's map.
    seconds : dict
        Wall time (s) of ``pose``, ``transfer``, ``fusion`` and ``total``.
    cpu_seconds : float
        CPU time of this process for the whole step.
    cpu : dict
        CPU time (s) of ``pose``, ``transfer`` and ``fusion``.
    reason : str
        Why the frame is lost or not initialised ("" otherwise).
    """

    index: int
    status: str
    pose: np.ndarray | None
    labels: np.ndarray | None
    tracking: TrackingResult | None = None
    fused: bool = False
    seconds: dict = field(default_factory=dict)
    cpu_seconds: float = 0.0
    reason: str = ""
    cpu: dict = field(default_factory=dict)

    @property
    def has_pose(self) -> bool:
        """True when the frame has a pose (and its labels are transferred, not void)."""
        return self.pose is not None


class RobotSession:
    """A robot's online session: localise, transfer and fuse one frame at a time.

    Parameters
    ----------
    person_map : SemanticMap or None
        The person's semantic map (a mesh for tracking against it). None: no transfer, the robot
        tracks against its own map (KinectFusion style) and fuses geometry (and ``probs``).
    method : str
        A registered transfer method (:func:`semmatch.transfer.available_methods`), ``fused``
        included (then every :meth:`step` needs ``probs``).
    params : dict, optional
        Method parameters (``--param``).
    index : MapIndex, optional
        The person's map's prebuilt index (e.g. :func:`semmatch.transfer.load_index`); default:
        built from ``person_map`` with ``max_distance``.
    max_distance : float, optional
        Transfer distance threshold (metres).
    voxel_size : float
        The robot's semantic TSDF voxel (metres).
    tsdf_options : dict, optional
        Passed to :class:`~semmatch.fusion.tsdf.SemanticTSDF` (``depth_max``, ``label_stride`` ...).
    init_pose : (4, 4), optional
        The first frame's pose (:func:`~semmatch.online.initialisation.given_pose`).
    initialiser : callable, optional
        ``init(frame, person_map) -> Initialisation``; default: ``init_pose`` when given, else
        :func:`~semmatch.online.initialisation.register_frame` with a person's map, else the identity.
    tracker : ModelTracker, optional
        Default: ``ModelTracker(person_map)``.
    relocalise_every : int
        While lost, call the initialiser again every this many frames (the frames between try
        tracking from the last good pose).
    """

    def __init__(self, person_map: SemanticMap | None = None, *, method: str = "3d-neighborhood",
                 params: dict | None = None, index=None, max_distance: float | None = None,
                 voxel_size: float = 0.04, tsdf_options: dict | None = None, init_pose: np.ndarray | None = None,
                 initialiser: Initialiser | None = None, tracker: ModelTracker | None = None,
                 relocalise_every: int = 10) -> None:
        from ..fusion import SemanticTSDF
        from ..transfer import as_map_index
        from ..transfer.registry import available_methods, check_params

        if method not in available_methods():
            raise ValueError(f"unknown transfer method {method!r}; valid: {', '.join(available_methods())}")
        self.params = dict(params or {})
        check_params(method, self.params)
        if int(relocalise_every) < 1:
            raise ValueError(f"relocalise_every must be >= 1, got {relocalise_every}")
        self.method = method
        self.person_map = person_map
        self.index = None
        if person_map is not None or index is not None:
            self.index = index if index is not None else as_map_index(person_map, max_distance=max_distance)
        self.max_distance = max_distance
        self.tsdf = SemanticTSDF(voxel_size, **(tsdf_options or {}))
        if initialiser is None:
            if init_pose is not None:
                initialiser = given_pose(init_pose)
            elif person_map is not None:
                initialiser = register_frame
            else:
                initialiser = given_pose(np.eye(4))
        self.initialiser = initialiser
        self._tracker = tracker
        self.relocalise_every = int(relocalise_every)
        self.last_pose: np.ndarray | None = None  # pose of the last frame with one
        self.motion = np.eye(4)  # per-frame motion (constant velocity)
        self._last_prior: np.ndarray | None = None
        self.lost_run = 0  # frames lost in a row
        self.n_lost = 0
        self.frames = 0

    @property
    def tracker(self) -> ModelTracker:
        """The frame-to-model tracker (built on first use: it ray casts the person's mesh)."""
        if self._tracker is None:
            self._tracker = ModelTracker(self.person_map)
        return self._tracker

    # ------------------------------------------------------------------ pose
    def predict(self, prior: np.ndarray | None = None) -> np.ndarray:
        """The predicted pose of the next frame: the odometry prior's motion since the last frame
        with a pose, else constant velocity."""
        if prior is not None and self._last_prior is not None:
            return self.last_pose @ np.linalg.inv(self._last_prior) @ prior
        return self.last_pose @ self.motion

    def _initialise(self, frame: Frame, *, relocalise: bool) -> tuple[np.ndarray | None, str, TrackingResult | None,
                                                                        str]:
        init: Initialisation = self.initialiser(frame, self.person_map)
        if init.pose is None:
            return None, LOST if relocalise else "initialising", None, f"{init.method}: no pose found"
        if not relocalise:
            return np.asarray(init.pose, dtype=np.float64), "initialised", None, ""
        tr = self.tracker.track(frame, np.asarray(init.pose, dtype=np.float64), robot=self.tsdf)  # verify it
        if tr.status != TRACKED:
            return None, LOST, tr, f"relocalisation by {init.method} not confirmed: {tr.reason}"
        return tr.pose, "relocalised", tr, ""

    def _pose(self, frame: Frame, prior: np.ndarray | None):
        if self.last_pose is None:
            return self._initialise(frame, relocalise=False)
        if self.lost_run and self.lost_run % self.relocalise_every == 0 and self.person_map is not None:
            return self._initialise(frame, relocalise=True)
        predicted = self.predict(prior) if not self.lost_run else (
            self.predict(prior) if prior is not None else self.last_pose)
        tr = self.tracker.track(frame, predicted, robot=self.tsdf)
        if tr.status == TRACKED:
            return tr.pose, "relocalised" if self.lost_run else TRACKED, tr, ""
        return None, LOST, tr, tr.reason

    # ------------------------------------------------------------------ one frame
    def step(self, frame: Frame, *, pose: np.ndarray | None = None, prior: np.ndarray | None = None,
             probs: np.ndarray | None = None) -> FrameResult:
        """Process one frame: pose, labels, fusion.

        Parameters
        ----------
        frame : Frame
            RGB-D frame (metric depth; its own ``pose`` is ignored unless passed as ``pose``).
        pose : (4, 4), optional
            Use this pose instead of tracking (status ``given``).
        prior : (4, 4), optional
            An odometry prior of this frame (wheel odometry, IMU) in any fixed frame: its motion
            since the last frame with a pose predicts this frame's pose.
        probs : float (H, W, C), optional
            The frame's class probabilities (``fused`` needs them; without a person's map they
            are fused as the labels).

        Returns
        -------
        FrameResult

        Raises
        ------
        ValueError
            A bad pose, ``fused`` without ``probs``, a frame that breaks the frame contract.
        """
        from ..fusion.reconstruction import fuse_frame
        from ..transfer.sequence import transfer_posed_frame

        where = f"frame {frame.index}"
        c0, t0 = time.process_time(), time.perf_counter()
        tr, reason = None, ""
        if pose is not None:
            T, status = check_pose(pose, what=f"{where} pose"), "given"
        else:
            T, status, tr, reason = self._pose(frame, None if prior is None else check_pose(prior, what=f"{where} prior"))
        t1, c1 = time.perf_counter(), time.process_time()
        labels = None
        if self.index is not None:
            if T is None:
                labels = np.zeros(frame.intrinsics.shape, np.uint8)
            else:
                extra = {} if probs is None else {"probs": probs}
                labels = transfer_posed_frame(self.method, frame, self.index, pose=T, max_distance=self.max_distance,
                                              **self.params, **extra).labels
        elif probs is not None:
            labels = probs
        t2, c2 = time.perf_counter(), time.process_time()
        fused = False
        if T is not None:
            fused = fuse_frame(self.tsdf, frame, T, labels, where=where)
            moved = self.last_pose is not None and status in (TRACKED, "given")
            self.motion = np.linalg.inv(self.last_pose) @ T if moved else np.eye(4)
            self.last_pose, self._last_prior, self.lost_run = T, prior, 0
        else:
            self.lost_run += 1
            self.n_lost += status == LOST
        self.frames += 1
        t3, c3 = time.perf_counter(), time.process_time()
        seconds = {"pose": t1 - t0, "transfer": t2 - t1, "fusion": t3 - t2, "total": t3 - t0}
        cpu = {"pose": c1 - c0, "transfer": c2 - c1, "fusion": c3 - c2}
        return FrameResult(frame.index, status, None if T is None else np.asarray(T, np.float64).copy(),
                           labels if labels is None or labels.ndim == 2 else None, tr, fused, seconds,
                           c3 - c0, reason, cpu)

    # ------------------------------------------------------------------ the map
    def semantic_map(self, output: str = "mesh", *, min_weight: float = 1.0) -> SemanticMap:
        """The robot's semantic map so far (:func:`semmatch.fusion.extract` of its TSDF)."""
        from ..fusion import extract

        return extract(self.tsdf, output, min_weight=min_weight)
