"""Frame-to-model tracking of one RGB-D frame against a rendered model view.

The frame (shrunk to the tracking size) is registered onto the model rendered from the predicted
pose (:func:`semmatch.online.rendering.render_view`) with the multi-scale RGB-D odometry of
:mod:`semmatch.poses.rgbd_odometry` (Open3D's kernels, repeatable run to run); the result is a
correction of the predicted pose. The quality of the fit (Open3D's fitness: the share of the
tracking image's pixels with a correspondence, and the inlier RMSE), the size of the correction
and the model's coverage decide whether the frame counts as tracked or lost.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..io import Frame, depth_to_uint16
from ..io.geometry import Intrinsics
from ..poses.trajectory_metrics import rotation_deg
from .rendering import MeshRenderer, ModelView, render_view

__all__ = ["TrackingResult", "ModelTracker", "TRACKED", "LOST"]

TRACKED, LOST = "tracked", "lost"


@dataclass
class TrackingResult:
    """The outcome of :meth:`ModelTracker.track`.

    Attributes
    ----------
    pose : (4, 4) float64 or None
        ``T_world_camera`` (None when lost).
    status : str
        ``"tracked"`` or ``"lost"``.
    fitness : float
        Share of the tracking image's pixels with a model correspondence in the last iteration.
    rmse : float
        Inlier RMSE of the last iteration (Open3D's residual).
    model : str
        What the model view came from (``person``, ``robot``, ``person+robot``, ``none``).
    model_share : float
        Share of the frame's depth pixels the model view covers.
    correction : (float, float)
        Translation (m) and rotation (degrees) of the correction to the predicted pose.
    reason : str
        Why a frame was lost ("" when tracked).
    view : ModelView or None
        The rendered model view (kept for reuse and display).
    """

    pose: np.ndarray | None
    status: str
    fitness: float = 0.0
    rmse: float = float("nan")
    model: str = "none"
    model_share: float = 0.0
    correction: tuple[float, float] = (float("nan"), float("nan"))
    reason: str = ""
    view: ModelView | None = None


class ModelTracker:
    """Track frames against a model rendered from their predicted pose.

    Parameters
    ----------
    person_map : SemanticMap or None
        The person's mesh map (None: track against the robot's own TSDF only).
    downsample : int, optional
        Track on frames shrunk by this factor (1: full size; 4 turns 640x480 into 160x120);
        default: the factor that brings the width nearest to 160 pixels (at least 1).
    iterations : sequence of int
        Odometry iterations per pyramid level, coarsest first (its length is the pyramid's levels).
    residual : {"point-to-plane", "hybrid", "intensity"}
        Odometry residual. Point-to-plane (geometry only, as KinectFusion) by default: on kitchen
        frames 0-499 and on simulated frames, the hybrid residual against a rendered model view
        drifted (docs/online.md).
    depth_max : float
        Ignore depth beyond this (metres).
    min_fitness : float
        Lost below this fitness.
    max_rmse : float
        Lost above this inlier RMSE.
    max_correction : (float, float)
        Lost when the correction of the predicted pose exceeds this translation (m) or rotation (deg).
    min_model_share : float
        Lost when the model view covers less than this share of the frame's depth pixels.
    min_person_share : float
        Render the robot's TSDF as well when the person's map fills less than this share.
    """

    def __init__(self, person_map=None, *, downsample: int | None = None, iterations=(10, 5), residual: str = "point-to-plane",
                 depth_max: float = 4.0, min_fitness: float = 0.2, max_rmse: float = 0.05,
                 max_correction: tuple[float, float] = (0.3, 30.0), min_model_share: float = 0.1,
                 min_person_share: float = 0.6) -> None:
        from ..poses.rgbd_odometry import METHODS

        if residual not in METHODS:
            raise ValueError(f"residual must be one of {METHODS}, got {residual!r}")
        if downsample is not None and int(downsample) < 1:
            raise ValueError(f"downsample must be an integer >= 1, got {downsample}")
        if len(iterations) < 1 or any(int(i) < 1 for i in iterations):
            raise ValueError(f"iterations must be one or more counts >= 1 (coarsest level first), got {iterations}")
        self.person = None if person_map is None else MeshRenderer(person_map)
        self.downsample = None if downsample is None else int(downsample)
        self.iterations = tuple(int(i) for i in iterations)
        self.residual = residual
        self.depth_max = float(depth_max)
        self.min_fitness, self.max_rmse = float(min_fitness), float(max_rmse)
        self.max_correction = (float(max_correction[0]), float(max_correction[1]))
        self.min_model_share = float(min_model_share)
        self.min_person_share = float(min_person_share)
        self._intr: dict[Intrinsics, Intrinsics] = {}

    def factor(self, intrinsics: Intrinsics) -> int:
        """The shrink factor for frames of this camera."""
        if self.downsample is not None:
            return self.downsample
        return max(1, int(round(intrinsics.width / 160)))

    def tracking_intrinsics(self, intrinsics: Intrinsics) -> Intrinsics:
        """The camera of the tracking images (the frame's, scaled by ``1 / downsample``)."""
        small = self._intr.get(intrinsics)
        if small is None:
            s = self.factor(intrinsics)
            small = self._intr[intrinsics] = intrinsics.scaled(intrinsics.width // s, intrinsics.height // s)
        return small

    def _pyramid(self, depth: np.ndarray, rgb: np.ndarray | None, intr: Intrinsics):
        from ..poses.rgbd_odometry import rgbd_pyramid

        return rgbd_pyramid(depth_to_uint16(depth), rgb, intr.K, levels=len(self.iterations), depth_max=self.depth_max)

    def shrink(self, frame: Frame, *, colour: bool = True) -> tuple[np.ndarray, np.ndarray | None, Intrinsics]:
        """The frame's depth (nearest pixel, as :func:`semmatch.poses.odometry.shrink_frame`) and
        colour (area-averaged; None without ``colour``) at the tracking size, and their camera."""
        from ..poses.odometry import shrink_frame

        s = self.factor(frame.intrinsics)
        intr = self.tracking_intrinsics(frame.intrinsics)
        if colour:
            small = shrink_frame(frame, s)
            depth, rgb = small.depth, small.rgb
        else:  # depth alone: shrink_frame's nearest pixel is the top-left one of each block
            depth, rgb = frame.depth[: intr.height * s: s, : intr.width * s: s], None
        return np.where(np.isfinite(depth), depth, 0).astype(np.float32), rgb, intr

    def track(self, frame: Frame, predicted: np.ndarray, robot=None) -> TrackingResult:
        """Register ``frame`` onto the model view at ``predicted`` (``T_world_camera``).

        Parameters
        ----------
        frame : Frame
            RGB-D frame (metric depth; RGB for the photometric residuals).
        predicted : (4, 4)
            Predicted pose (constant velocity or an odometry prior).
        robot : SemanticTSDF, optional
            The robot's map (the model where the person's map is missing or absent).

        Returns
        -------
        TrackingResult
        """
        from ..poses.rgbd_odometry import multi_scale_odometry

        photometric = self.residual != "point-to-plane" and frame.rgb is not None
        depth, rgb, intr = self.shrink(frame, colour=photometric)
        valid = int(np.count_nonzero((depth > 0) & (depth <= self.depth_max)))
        if valid < 0.01 * depth.size:
            return TrackingResult(None, LOST, reason="no depth in the frame")
        view = render_view(predicted, intr, person=self.person, robot=robot, depth_max=self.depth_max,
                           min_person_share=self.min_person_share, frame_valid=valid, colour=photometric)
        share = min(view.n_valid / valid, 1.0)
        if share < 0.5 and view.source != "person" and robot is not None:
            # Open3D's ray caster leaves its view incomplete on the call that outgrows its range-map
            # buffer (it warns and reallocates for the next call): render once more
            again = render_view(predicted, intr, person=self.person, robot=robot, depth_max=self.depth_max,
                                min_person_share=self.min_person_share, frame_valid=valid, colour=photometric)
            if again.n_valid > view.n_valid:
                view, share = again, min(again.n_valid / valid, 1.0)
        if share < self.min_model_share:
            return TrackingResult(None, LOST, model=view.source, model_share=share, view=view,
                                  reason=f"the model covers {share:.0%} of the view")
        residual = self.residual if photometric else "point-to-plane"
        src = self._pyramid(depth, rgb, intr)
        tgt = self._pyramid(view.depth, view.rgb, intr)
        try:
            T, fitness, rmse = multi_scale_odometry(src, tgt, np.eye(4), method=residual, iterations=self.iterations)
        except RuntimeError:
            return TrackingResult(None, LOST, model=view.source, model_share=share, view=view,
                                  reason="no correspondences")
        dt, dr = float(np.linalg.norm(T[:3, 3])), rotation_deg(T[:3, :3]) if np.isfinite(T).all() else float("nan")
        common = dict(fitness=float(fitness), rmse=float(rmse), model=view.source, model_share=share,
                      correction=(dt, dr), view=view)
        why = ""
        if not np.isfinite(T).all():
            why = "diverged"
        elif dt > self.max_correction[0] or dr > self.max_correction[1]:
            why = f"correction {dt:.2f} m / {dr:.0f} deg is implausible"
        elif fitness < self.min_fitness:
            why = f"fitness {fitness:.2f} < {self.min_fitness}"
        elif rmse > self.max_rmse:
            why = f"residual {rmse:.3f} > {self.max_rmse}"
        if why:
            return TrackingResult(None, LOST, reason=why, **common)
        return TrackingResult(predicted @ T, TRACKED, **common)
